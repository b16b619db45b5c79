//! Every file jsim writes, by command: the one list of output names, and the names themselves (the constants
//! and `*_name` functions below), which the writers and the readers of those files take from here.
//! `engine/tests/output_files.rs` runs each command and fails on a file in its output directory that is not
//! declared here for it, and on a declared name that no page of docs/ describes.
//!
//! A pattern is a path relative to the command's output directory, in the docs' own notation: a part in
//! braces stands for one or more digits when it is a number (`{NNN}`, `{k}`), else for one or more characters
//! other than `/` (`img_{NNN}.fits` is documented as `img_NNN.fits`, `ARRAY{k}/` as `ARRAYk/`,
//! `stars_{<case>}.csv` as `stars_<case>.csv`).

/// The command that writes a file (its output directory: `--out`, or `jsim solve`'s `solution/`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    Simulate,
    Analyze,
    Score,
    Experiment,
    Crowded,
    Sequence,
    Solve,
    SolveSynthetic,
    Transit,
    Sweep,
    Merge,
    Report,
    Bench,
}

/// One declared output: its pattern, the commands that write it, and what it holds (one line).
#[derive(Debug, Clone, Copy)]
pub struct OutputFile {
    pub pattern: &'static str,
    pub by: &'static [Command],
    pub what: &'static str,
}

use Command::*;

const fn f(pattern: &'static str, by: &'static [Command], what: &'static str) -> OutputFile {
    OutputFile { pattern, by, what }
}

/// The fixed names of [`OUTPUT_FILES`] (relative to the command's output directory), for their writers and
/// readers.
pub const FLAT_CAL_FITS: &str = "flat_cal.fits";
pub const PSF_MODEL_FITS: &str = "psf_model.fits";
pub const REFCAT_CSV: &str = "refcat.csv";
pub const RUN_JSON: &str = "run.json";
pub const CONFIG_TOML: &str = "config.toml";
pub const CATALOGUE_CSV: &str = "catalogue.csv";
pub const EPSF_FITS: &str = "epsf.fits";
pub const SUMMARY_JSON: &str = "summary.json";
pub const VECTORS_CSV: &str = "vectors.csv";
pub const VECTORS_PNG: &str = "vectors.png";
pub const CROWDED_BINS_CSV: &str = "crowded_bins.csv";
pub const REPEATABILITY_CSV: &str = "repeatability.csv";
pub const SCORE_CSV: &str = "score.csv";
pub const SCORE_JSON: &str = "score.json";
pub const EXPERIMENT_CSV: &str = "experiment.csv";
pub const IMAGES_CSV: &str = "images.csv";
pub const ACCURACY_PNG: &str = "accuracy.png";
pub const CROWDED_ARRAYS_CSV: &str = "crowded_arrays.csv";
pub const ACCURACY_VS_MAG_PNG: &str = "accuracy_vs_mag.png";
pub const SEQUENCE_TOML: &str = "sequence.toml";
pub const DESIGN_TOML: &str = "design.toml";
pub const SEQUENCE_JSON: &str = "sequence.json";
pub const PLAN_CSV: &str = "plan.csv";
pub const PLAN_TRUTH_CSV: &str = "plan_truth.csv";
pub const COVERAGE_CSV: &str = "coverage.csv";
pub const COVERAGE_PNG: &str = "coverage.png";
pub const FIELD_CSV: &str = "field.csv";
pub const FIELD_BRIGHT_CSV: &str = "field_bright.csv";
pub const REFERENCE_CSV: &str = "reference.csv";
pub const CATALOGUE_FITS: &str = "catalogue.fits";
pub const SLURM_ARRAY_SBATCH: &str = "slurm/array.sbatch";
pub const SLURM_GATHER_SBATCH: &str = "slurm/gather.sbatch";
pub const SLURM_SUBMIT_SH: &str = "slurm/submit.sh";
pub const SOURCES_CSV: &str = "sources.csv";
pub const ATTITUDES_CSV: &str = "attitudes.csv";
pub const CALIBRATION_CSV: &str = "calibration.csv";
pub const CALIBRATION_MAP_CSV: &str = "calibration_map.csv";
pub const SCORE_SOURCES_CSV: &str = "score_sources.csv";
pub const SCORE_ATTITUDES_CSV: &str = "score_attitudes.csv";
pub const PRECISION_VS_N_CSV: &str = "precision_vs_n.csv";
pub const PRECISION_VS_N_PNG: &str = "precision_vs_n.png";
pub const MISSION_BUDGET_CSV: &str = "mission_budget.csv";
pub const SOLUTION_JSON: &str = "solution.json";
pub const SLURM_SOLVE_SBATCH: &str = "slurm/solve.sbatch";
pub const SLURM_SUBMIT_SOLVE_SH: &str = "slurm/submit-solve.sh";
pub const LIGHTCURVE_ECSV: &str = "lightcurve.ecsv";
pub const LIGHTCURVE_PNG: &str = "lightcurve.png";
pub const TRUTH_ECSV: &str = "truth.ecsv";
pub const TRANSIT_JSON: &str = "transit.json";
pub const WINDOWS_FITS: &str = "windows.fits";
pub const TELEMETRY_ECSV: &str = "telemetry.ecsv";
pub const PRECISION_CSV: &str = "precision.csv";
pub const PRECISION_JSON: &str = "precision.json";
pub const PRECISION_PNG: &str = "precision.png";
pub const SWEEP_JSON: &str = "sweep.json";
pub const POINTS_CSV: &str = "points.csv";
pub const SLURM_MERGE_SBATCH: &str = "slurm/merge.sbatch";
pub const MERGED_CSV: &str = "merged.csv";
pub const MERGED_JSON: &str = "merged.json";
pub const REPORT_CSV: &str = "report.csv";
pub const REPORT_FRACTION_PNG: &str = "report/fraction.png";
pub const BENCH_CSV: &str = "bench.csv";
pub const BENCH_PNG: &str = "bench.png";

/// `img_{NNN}.fits`: one array's exposure `index`.
pub fn image_name(index: usize) -> String {
    format!("img_{index:03}.fits")
}

/// `truth_{NNN}.csv`: the truth catalogue of image `index`.
pub fn truth_name(index: usize) -> String {
    format!("truth_{index:03}.csv")
}

/// `fp_{NNN}.fits`: focal-plane exposure `index`.
pub fn focal_plane_name(index: usize) -> String {
    format!("fp_{index:03}.fits")
}

/// `telemetry_{NNN}.fits`: the attitude telemetry of exposure `index` beside the images.
pub fn telemetry_name(index: usize) -> String {
    format!("telemetry_{index:03}.fits")
}

/// `exposures/{NNNNN}.csv`: a sequence's exposure `index`'s catalogue.
pub fn sequence_catalogue_name(index: usize) -> String {
    format!("exposures/{index:05}.csv")
}

/// `exposures/{NNNNN}_truth.csv`: the scoring's match of a sequence's exposure `index` to the truth.
pub fn sequence_truth_name(index: usize) -> String {
    format!("exposures/{index:05}_truth.csv")
}

/// `exposures/fp_{NNNNN}.fits`: a sequence's kept image of exposure `index`.
pub fn sequence_image_name(index: usize) -> String {
    format!("exposures/fp_{index:05}.fits")
}

/// Every file jsim writes into an output directory. (`jsim psf --out FILE` and `jsim ace --out FILE` write the
/// one file they are given.)
#[rustfmt::skip]
pub const OUTPUT_FILES: &[OutputFile] = &[
    // jsim simulate: the images, their truth and the instrument's products
    f("img_{NNN}.fits", &[Simulate], "one array's exposure: image, DQ, TRUTH, CONFIG"),
    f("fp_{NNN}.fits", &[Simulate], "one focal-plane exposure: ARRAY1 … ARRAY4, DQ1 … DQ4, TRUTH, CONFIG"),
    f("truth_{NNN}.csv", &[Simulate], "the TRUTH table of one array's exposure as CSV (scoring's side)"),
    f("telemetry_{NNN}.fits", &[Simulate], "the attitude telemetry product of an exposure"),
    f(FLAT_CAL_FITS, &[Simulate], "the calibration flat product"),
    f(PSF_MODEL_FITS, &[Simulate], "the design model PSF product"),
    f(REFCAT_CSV, &[Simulate], "the reference catalogue product"),
    f(RUN_JSON, &[Simulate], "the run's seed, timings and account of the stars"),
    f(CONFIG_TOML, &[Simulate, Sequence], "the configuration as run"),
    // jsim analyze (and its per-array and per-chip directories)
    f(CATALOGUE_CSV, &[Analyze], "the fitted stars"),
    f(EPSF_FITS, &[Analyze], "the ePSF built from the stars"),
    f(SUMMARY_JSON, &[Analyze], "the analysis' report"),
    f(VECTORS_CSV, &[Analyze], "the deviation vector map's data"),
    f(VECTORS_PNG, &[Analyze], "the deviation vector map"),
    f(CROWDED_BINS_CSV, &[Analyze, Crowded], "accuracy and completeness per bin of true Hw"),
    f("ARRAY{k}/catalogue.csv", &[Analyze], "one array's fitted stars (a focal-plane file)"),
    f("ARRAY{k}/epsf.fits", &[Analyze], "one array's ePSF"),
    f("ARRAY{k}/summary.json", &[Analyze], "one array's report"),
    f("SCI{k}/catalogue.csv", &[Analyze], "one chip's fitted stars (a calibrated file)"),
    f("SCI{k}/epsf.fits", &[Analyze], "one chip's ePSF"),
    f("SCI{k}/summary.json", &[Analyze], "one chip's report"),
    f("SCI{k}/cosmic_rays.fits", &[Analyze], "one chip's cosmic-ray mask"),
    f("GROUP{k}/catalogue.csv", &[Analyze], "one chip's fitted stars (a waivered file)"),
    f("GROUP{k}/epsf.fits", &[Analyze], "one chip's ePSF (a waivered file)"),
    f("GROUP{k}/summary.json", &[Analyze], "one chip's report (a waivered file)"),
    f("GROUP{k}/cosmic_rays.fits", &[Analyze], "one chip's cosmic-ray mask (a waivered file)"),
    // after SCI and GROUP: a name matches the first pattern that fits it
    f("{EXTNAME}{k}/catalogue.csv", &[Analyze], "one chip's fitted stars (a file of image extensions)"),
    f("{EXTNAME}{k}/epsf.fits", &[Analyze], "one chip's ePSF (a file of image extensions)"),
    f("{EXTNAME}{k}/summary.json", &[Analyze], "one chip's report (a file of image extensions)"),
    f("{EXTNAME}{k}/cosmic_rays.fits", &[Analyze], "one chip's cosmic-ray mask (a file of image extensions)"),
    f(REPEATABILITY_CSV, &[Analyze], "repeatability against the bound, exposures of one pointing"),
    // jsim score
    f(SCORE_CSV, &[Score], "completeness and accuracy per bin of true magnitude"),
    f(SCORE_JSON, &[Score], "the same, the false detections, the common offset, the frame"),
    // jsim experiment
    f(EXPERIMENT_CSV, &[Experiment], "accuracy per case, countermeasure and magnitude"),
    f(IMAGES_CSV, &[Experiment], "per image: accuracy, bound, timings"),
    f(ACCURACY_PNG, &[Experiment], "accuracy against magnitude"),
    f("vectors_{<ace>_<readout>_<mag>}.png", &[Experiment], "the vector map of the first magnitude"),
    f("vectors_{<ace>_<readout>_<mag>}.csv", &[Experiment], "its data"),
    // jsim crowded
    f(CROWDED_ARRAYS_CSV, &[Crowded], "per case and array: detections, ePSF, groups, time"),
    f("stars_{<case>}.csv", &[Crowded], "every reported star of a case"),
    f(ACCURACY_VS_MAG_PNG, &[Crowded], "accuracy against magnitude per case"),
    f("vectors_{<case>_<countermeasure>}.png", &[Crowded], "the four arrays' vector maps"),
    f("{<case>}/fp_000.fits", &[Crowded], "with --save-images: the case's exposure"),
    f("{<case>}/flat_cal.fits", &[Crowded], "with --save-images: its calibration flat"),
    f("{<case>}/psf_model.fits", &[Crowded], "with --save-images: its design model PSF"),
    f("{<case>}/refcat.csv", &[Crowded], "with --save-images: its reference catalogue"),
    f("{<case>}/telemetry_000.fits", &[Crowded], "with --save-images: its telemetry (a moving ACE)"),
    // jsim sequence
    f(SEQUENCE_TOML, &[Sequence], "the sequence's spec as run"),
    f(DESIGN_TOML, &[Sequence], "the design configuration the solution reads"),
    f(SEQUENCE_JSON, &[Sequence], "the plan's summary"),
    f(PLAN_CSV, &[Sequence], "every planned exposure"),
    f(PLAN_TRUTH_CSV, &[Sequence], "each exposure's true pointing (scoring's side)"),
    f(COVERAGE_CSV, &[Sequence], "exposures per sky cell"),
    f(COVERAGE_PNG, &[Sequence], "the coverage map"),
    f(FIELD_CSV, &[Sequence], "the field's stars (scoring's side)"),
    f(FIELD_BRIGHT_CSV, &[Sequence], "with persistence: the stars bright enough to fill traps"),
    f(REFERENCE_CSV, &[Sequence], "the survey's reference catalogue"),
    f("exposures/{NNNNN}.csv", &[Sequence], "one exposure's catalogue"),
    f("exposures/{NNNNN}_truth.csv", &[Sequence], "one exposure's truth (scoring's side)"),
    f("exposures/fp_{NNNNN}.fits", &[Sequence], "with --keep-images: one exposure's image"),
    f(CATALOGUE_FITS, &[Sequence], "every exposure's catalogue gathered"),
    f(SLURM_ARRAY_SBATCH, &[Sequence, Sweep], "with --emit-slurm: the job array"),
    f(SLURM_GATHER_SBATCH, &[Sequence], "with --emit-slurm: the gathering job"),
    f(SLURM_SUBMIT_SH, &[Sequence, Sweep], "with --emit-slurm: submits the jobs in order"),
    // jsim solve (its output directory, default solution/ in the sequence's) and jsim solve-synthetic
    f(SOURCES_CSV, &[Solve, SolveSynthetic], "each source's solved astrometry"),
    f(ATTITUDES_CSV, &[Solve, SolveSynthetic], "each exposure's solved attitude"),
    f(CALIBRATION_CSV, &[Solve], "the solved calibration terms"),
    f(CALIBRATION_MAP_CSV, &[Solve], "the solved distortion on a grid"),
    f(SCORE_SOURCES_CSV, &[Solve], "the sources against the truth (scoring)"),
    f(SCORE_ATTITUDES_CSV, &[Solve], "the attitudes against the truth (scoring)"),
    f(PRECISION_VS_N_CSV, &[Solve], "the precision against the number of exposures"),
    f(PRECISION_VS_N_PNG, &[Solve], "its figure"),
    f(MISSION_BUDGET_CSV, &[Solve], "the mission's error budget from the measured precision"),
    f(SOLUTION_JSON, &[Solve, SolveSynthetic], "the solution's report"),
    f(SLURM_SOLVE_SBATCH, &[Solve], "with --emit-slurm, in the sequence's directory: the MPI job"),
    f(SLURM_SUBMIT_SOLVE_SH, &[Solve], "with --emit-slurm, in the sequence's directory: submits it"),
    // jsim transit
    f(LIGHTCURVE_ECSV, &[Transit], "the differential light curve"),
    f(LIGHTCURVE_PNG, &[Transit], "its figure"),
    f(TRUTH_ECSV, &[Transit], "the injected transit and the true jitter (scoring's side)"),
    f(TRANSIT_JSON, &[Transit], "the stare, its precision, budget and recovery"),
    f(WINDOWS_FITS, &[Transit], "with --write-products: every window of every plate"),
    f(TELEMETRY_ECSV, &[Transit], "with --write-products: the attitude per plate"),
    f(PRECISION_CSV, &[Transit], "with --magnitudes: the precision against magnitude"),
    f(PRECISION_JSON, &[Transit], "with --magnitudes: the same as JSON"),
    f(PRECISION_PNG, &[Transit], "with --magnitudes: its figure"),
    f("hw_{M}/lightcurve.ecsv", &[Transit], "with --magnitudes: each stare's light curve"),
    f("hw_{M}/lightcurve.png", &[Transit], "with --magnitudes: each stare's figure"),
    f("hw_{M}/truth.ecsv", &[Transit], "with --magnitudes: each stare's truth"),
    f("hw_{M}/transit.json", &[Transit], "with --magnitudes: each stare's report"),
    f(
        "hw_{M}/row.json",
        &[Transit],
        "with --magnitudes: each finished stare's row and fingerprint (a rerun resumes from them)",
    ),
    // jsim sweep, merge, report
    f(SWEEP_JSON, &[Sweep], "the sweep's spec and its points"),
    f(POINTS_CSV, &[Sweep], "the grid's points"),
    f("points/point-{NNN}.toml", &[Sweep], "each point's configuration"),
    f("shards/shard-{NNNN}-of-{NNNN}.csv", &[Sweep], "one shard's rows"),
    f("shards/shard-{NNNN}-of-{NNNN}.json", &[Sweep], "one shard's state"),
    f("shards/shard-{NNNN}-of-{NNNN}.lock", &[Sweep], "one shard's lock"),
    f(SLURM_MERGE_SBATCH, &[Sweep], "with --emit-slurm: the merging job"),
    f(MERGED_CSV, &[Merge], "every unit's row"),
    f(MERGED_JSON, &[Merge], "the merge's diagnostics"),
    f(REPORT_CSV, &[Report], "the fraction meeting the threshold per point"),
    f(REPORT_FRACTION_PNG, &[Report], "the fractions against the grid"),
    f("report/dist_{p<point>_<countermeasure>}.png", &[Report], "each point's distribution"),
    // jsim bench
    f(BENCH_CSV, &[Bench], "time and error of each knob"),
    f(BENCH_PNG, &[Bench], "its figure"),
];

/// Whether `path` (relative, `/`-separated) matches `pattern`: literal characters match themselves, a part in
/// braces one or more digits (`{NNN}`, `{k}`) or one or more characters other than `/`.
pub fn matches(pattern: &str, path: &str) -> bool {
    match pattern.find('{') {
        None => pattern == path,
        Some(open) => {
            let Some(close) = pattern[open..].find('}').map(|c| open + c) else {
                return pattern == path;
            };
            let (lit, part, rest) = (
                &pattern[..open],
                &pattern[open + 1..close],
                &pattern[close + 1..],
            );
            let Some(tail) = path.strip_prefix(lit) else {
                return false;
            };
            // the wildcard takes 1 … n characters up to the first '/' (digits only for a number)
            let number = part.chars().all(|c| c == 'N') || part == "k";
            let limit = tail
                .find(|c: char| c == '/' || (number && !c.is_ascii_digit()))
                .unwrap_or(tail.len());
            (1..=limit).any(|n| tail.is_char_boundary(n) && matches(rest, &tail[n..]))
        }
    }
}

/// The declared output of `command` that `path` is, if any.
pub fn declared(command: Command, path: &str) -> Option<&'static OutputFile> {
    OUTPUT_FILES
        .iter()
        .find(|o| o.by.contains(&command) && matches(o.pattern, path))
}

/// A pattern as the docs write it: the braces dropped (`img_{NNN}.fits` → `img_NNN.fits`).
pub fn as_documented(pattern: &str) -> String {
    pattern.chars().filter(|c| *c != '{' && *c != '}').collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pattern_matches_its_own_names_and_no_other() {
        assert!(matches("img_{NNN}.fits", "img_000.fits"));
        assert!(matches("img_{NNN}.fits", "img_1234.fits"));
        assert!(!matches("img_{NNN}.fits", "img_.fits"));
        assert!(!matches("img_{NNN}.fits", "img_000.fits.tmp"));
        assert!(matches("ARRAY{k}/epsf.fits", "ARRAY3/epsf.fits"));
        assert!(!matches("ARRAY{k}/epsf.fits", "ARRAY3/x/epsf.fits"));
        assert!(matches(
            "shards/shard-{NNNN}-of-{NNNN}.csv",
            "shards/shard-0000-of-0001.csv"
        ));
        assert!(matches("{<case>}/fp_000.fits", "realistic/fp_000.fits"));
        assert!(!matches("catalogue.csv", "ARRAY1/catalogue.csv"));
        assert!(!matches(
            "exposures/{NNNNN}.csv",
            "exposures/00001_truth.csv"
        ));
        assert!(matches("hw_{M}/truth.ecsv", "hw_9.5/truth.ecsv"));
        assert_eq!(as_documented("hw_{M}/truth.ecsv"), "hw_M/truth.ecsv");
    }

    #[test]
    fn every_name_a_writer_takes_is_declared() {
        let named = [
            (Simulate, image_name(7)),
            (Simulate, truth_name(7)),
            (Simulate, focal_plane_name(12)),
            (Simulate, telemetry_name(0)),
            (Sequence, sequence_catalogue_name(31)),
            (Sequence, sequence_truth_name(31)),
            (Sequence, sequence_image_name(31)),
        ];
        for (by, name) in named {
            assert!(declared(by, &name).is_some(), "{name}");
        }
        // and a number's name is that number's (not another's that shares its digits)
        assert_eq!(image_name(1234), "img_1234.fits");
        assert_eq!(sequence_catalogue_name(3), "exposures/00003.csv");
    }

    #[test]
    fn every_pattern_is_declared_once_per_command() {
        for (i, a) in OUTPUT_FILES.iter().enumerate() {
            for b in &OUTPUT_FILES[i + 1..] {
                let shared = a.by.iter().any(|c| b.by.contains(c));
                assert!(!(shared && a.pattern == b.pattern), "{}", a.pattern);
            }
        }
    }
}
