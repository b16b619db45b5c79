//! File formats that know no schema: the records of a CSV file (the `csv` crate), FITS HDUs and cards (CFITSIO). What each file holds, its
//! columns and units, is `io`'s; the modules below `io` that read a user's file (a star catalogue, an
//! intra-pixel map) read its records here.

pub mod csv;
pub mod fits;
pub mod fits_reader;
