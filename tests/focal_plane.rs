//! The quad focal plane and scenes on the sky: where stars land, how every star is accounted for, the
//! jitter common to the four arrays and turned into each, and the hard cases of issue #15 (a star in a
//! gap, on an array's corner, duplicate rows, an empty field, a field where every star saturates, a row far
//! outside the field).

mod common;

use common::{small_config, temp_dir};
use engine::config::{AceCase, Config, Layout, SceneKind};
use engine::detector::dq;
use engine::scene::{self, PlacementCounts};
use engine::simulate::FocalPlaneSimulator;
use engine::sky;
use std::path::PathBuf;

/// The small test configuration on the quad focal plane, still and noise-free, stars at their catalogue
/// place (these tests pin the geometry with positions made through the arrays' WCS; the apparent place is
/// tested against astropy in `engine/python/tests/test_focal_plane.py`).
fn quad() -> Config {
    let mut c = small_config();
    c.observation.apparent_place = false;
    c.focal_plane.layout = Layout::Quad;
    c.focal_plane.gap_px = 60.0;
    c.ace.case = AceCase::None;
    c.fidelity.images = 1;
    engine::testkit::signal_only(&mut c);
    c
}

/// The sky position of array k's pixel (x, y).
fn sky_of(c: &Config, k: usize, x: f64, y: f64) -> (f64, f64) {
    let w = sky::array_wcs(c, k).expect("wcs");
    w.pixel_to_sky(x, y).expect("sky")
}

/// The catalogue file and its scratch directory (removed when the guard is dropped: keep it alive).
fn write_catalogue(name: &str, rows: &[(f64, f64, f64)]) -> (engine::testkit::Scratch, PathBuf) {
    let dir = temp_dir(name);
    let path = dir.join("stars.csv");
    let mut text = String::from("ra,dec,hw,j_h\n");
    for (ra, dec, hw) in rows {
        text += &format!("{ra:.12},{dec:.12},{hw},2.0\n");
    }
    std::fs::write(&path, text).expect("write catalogue");
    (dir, path)
}

#[test]
fn every_star_is_placed_or_counted_and_hard_cases_land_where_they_should() {
    let mut c = quad();
    let b = c.instrument.border_px() as f64; // first photosensitive pixel
    let centre0 = sky_of(&c, 0, 255.0, 256.0);
    let corner3 = sky_of(&c, 3, b, b); // the photosensitive corner pixel of array 3
    let border1 = sky_of(&c, 1, 2.0, 200.0); // on array 1's dead border, 6 px from its light
    let axis = (c.sky.ra_deg, c.sky.dec_deg); // the optical axis: the cross-shaped gap
    let antipode = ((c.sky.ra_deg + 180.0) % 360.0, -c.sky.dec_deg);
    let far = (c.sky.ra_deg, c.sky.dec_deg + 10.0);
    let (_dir, path) = write_catalogue(
        "fp-hard",
        &[
            (centre0.0, centre0.1, 12.0),
            (corner3.0, corner3.1, 12.5),
            (axis.0, axis.1, 12.0),
            (centre0.0, centre0.1, 12.0), // an exact duplicate of row 0
            (antipode.0, antipode.1, 12.0),
            (far.0, far.1, 12.0),
            (border1.0, border1.1, 11.0),
        ],
    );
    c.scene.kind = SceneKind::Catalogue;
    c.scene.catalogue = Some(path);
    let fps = FocalPlaneSimulator::new(&c).expect("focal plane");
    assert_eq!(
        fps.counts,
        Some(PlacementCounts {
            catalogue: 7,
            duplicates: 1,
            photosensitive: 2,
            border: 1,
            gap: 1,
            off: 2,
        })
    );
    let exp = fps.exposure(0).expect("exposure");
    // the truth holds exactly the two stars on photosensitive pixels, on their arrays, where the WCS puts them
    let truth: Vec<(usize, usize, f64, f64)> = exp
        .arrays
        .iter()
        .enumerate()
        .flat_map(|(k, e)| e.truth.iter().map(move |t| (k, t.id, t.x_px, t.y_px)))
        .collect();
    assert_eq!(truth.len(), 2, "{truth:?}");
    let (k, id, x, y) = truth[0];
    assert_eq!((k, id), (0, 0));
    assert!(
        (x - 255.0).abs() < 1e-6 && (y - 256.0).abs() < 1e-6,
        "{x} {y}"
    );
    let (k, id, x, y) = truth[1];
    assert_eq!((k, id), (3, 1));
    assert!((x - b).abs() < 1e-6 && (y - b).abs() < 1e-6, "{x} {y}");
    // the corner star's light is on array 3; the duplicate did not double row 0's light
    let n = c.instrument.detector_px;
    let sum_near = |e: &engine::simulate::Exposure, x: usize, y: usize, r: usize| -> f64 {
        let mut s = 0.0;
        for py in y.saturating_sub(r)..(y + r + 1).min(n) {
            for px in x.saturating_sub(r)..(x + r + 1).min(n) {
                s += e.star_e[py * n + px];
            }
        }
        s
    };
    let flux0 = exp.arrays[0].truth[0].flux_e;
    let got0 = sum_near(&exp.arrays[0], 255, 256, 14);
    let mf = exp.arrays[0].truth[0].modelled_fraction;
    let all: f64 = exp.arrays[0].star_e.iter().sum();
    // (a pixel sum of the kernel at one phase matches its light fraction to ≈ 3e-4; a doubled row is 2×)
    assert!(
        (got0 / (flux0 * mf) - 1.0).abs() < 1e-3,
        "row 0 once: {got0} of {flux0} × {mf}; the whole array holds {all}"
    );
    assert!(
        sum_near(&exp.arrays[3], b as usize, b as usize, 3) > 0.1 * exp.arrays[3].truth[0].flux_e
    );
    // the border star is not in the truth, but its wings light array 1's photosensitive edge (not dropped)
    let lit: f64 = (b as usize..b as usize + 4)
        .map(|x| sum_near(&exp.arrays[1], x, 200, 0))
        .sum();
    assert!(
        lit > 100.0,
        "border star's light on the photosensitive pixels: {lit} e⁻"
    );
    assert!(exp.arrays[1].truth.is_empty());
    // the gap star and the far rows are simulated on no array
    for a in &fps.arrays {
        assert!(a.stars.iter().all(|s| s.id != 2 && s.id != 4 && s.id != 5));
    }
}

#[test]
fn the_jitter_is_common_to_the_arrays_and_turned_into_each() {
    // one bright star on the same pixel of every array, every pixel with the same window (sample-and-hold):
    // each array's image is array 0's turned by its rotation — the PSF (spiders, aberrations) and the jitter
    // turn together
    let mut c = quad();
    c.readout.order = engine::config::ReadoutOrder::SampleHold;
    c.ace.case = AceCase::Realistic;
    c.ace.sigma_mas = 1500.0; // a mean offset over the exposure of a sizeable fraction of a pixel
    let rows: Vec<(f64, f64, f64)> = (0..4)
        .map(|k| {
            let (ra, dec) = sky_of(&c, k, 200.0, 300.0);
            (ra, dec, 10.0)
        })
        .collect();
    c.scene.kind = SceneKind::Catalogue;
    let (_dir, path) = write_catalogue("fp-jitter", &rows);
    c.scene.catalogue = Some(path);
    let fps = FocalPlaneSimulator::new(&c).expect("focal plane");
    let exp = fps.exposure(0).expect("exposure");
    let n = c.instrument.detector_px as i64;
    let r = 12i64;
    let (sx, sy) = (200i64, 300i64);
    let at = |k: usize, dx: i64, dy: i64| exp.arrays[k].star_e[((sy + dy) * n + sx + dx) as usize];
    let (mut cx0, mut cy0, mut s0) = (0.0, 0.0, 0.0);
    for dy in -r..=r {
        for dx in -r..=r {
            let v = at(0, dx, dy);
            cx0 += v * dx as f64;
            cy0 += v * dy as f64;
            s0 += v;
        }
    }
    let (cx0, cy0) = (cx0 / s0, cy0 / s0);
    assert!(
        cx0.hypot(cy0) > 0.05,
        "the jitter moved the star: ({cx0}, {cy0}) px"
    );
    for k in 1..4 {
        let rot = c.focal_plane.rotations_deg[k];
        let (sn, cs) = (-rot).to_radians().sin_cos();
        let mut worst: f64 = 0.0;
        for dy in -r..=r {
            for dx in -r..=r {
                // array k's offset d′ = R(−r)·d of array 0's offset d
                let (ex, ey) = (
                    (cs * dx as f64 - sn * dy as f64).round() as i64,
                    (sn * dx as f64 + cs * dy as f64).round() as i64,
                );
                worst = worst.max((at(k, ex, ey) - at(0, dx, dy)).abs());
            }
        }
        let peak = at(0, 0, 0).max(1.0);
        assert!(
            worst < 1e-8 * peak,
            "array {k}: worst pixel difference {worst} e⁻ (peak {peak})"
        );
        // and the truth's jitter is the same displacement turned into the array's axes
        let (t0, tk) = (&exp.arrays[0].truth[0], &exp.arrays[k].truth[0]);
        let (ex, ey) = (
            cs * t0.jitter_dx_px - sn * t0.jitter_dy_px,
            sn * t0.jitter_dx_px + cs * t0.jitter_dy_px,
        );
        assert!((tk.jitter_dx_px - ex).abs() < 1e-12 && (tk.jitter_dy_px - ey).abs() < 1e-12);
    }
    // each array has its own noise streams
    assert_ne!(fps.arrays[0].array.seed, fps.arrays[1].array.seed);
}

#[test]
fn an_empty_field_is_an_exposure_with_no_stars() {
    let mut c = quad();
    c.scene.kind = SceneKind::Bulge;
    c.scene.bulge.density_per_arcmin2 = 0.0;
    c.detector.dark_e_per_s = 24.5;
    let fps = FocalPlaneSimulator::new(&c).expect("focal plane");
    assert_eq!(fps.counts, Some(PlacementCounts::default()));
    let exp = fps.exposure(0).expect("exposure");
    for e in &exp.arrays {
        assert!(e.truth.is_empty());
        assert!(e.star_e.iter().all(|v| *v == 0.0));
    }
    let dir = temp_dir("fp-empty");
    let path =
        engine::io::focal_plane::write_focal_plane_exposure(&dir, &fps, &exp).expect("write");
    let ids = engine::io::fits::read_table(&path, "TRUTH", &["id"]).expect("truth");
    assert!(ids[0].is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_field_where_every_star_saturates_is_clipped_and_flagged() {
    let mut c = quad();
    c.ace.case = AceCase::Gaussian;
    c.detector.shot_noise = true;
    c.detector.read_noise = true;
    c.detector.digitise = true;
    c.scene.kind = SceneKind::Bulge;
    c.scene.bulge.density_per_arcmin2 = 0.5;
    c.scene.bulge.hw_min = 6.0;
    c.scene.bulge.hw_max = 9.0; // Hw ≲ 9.7 fills the 150 000-e⁻ well in 12.5 s
    c.scene.bulge.density_hw_limit = 9.0; // the density counts these stars alone
    let fps = FocalPlaneSimulator::new(&c).expect("focal plane");
    let exp = fps.exposure(0).expect("exposure");
    let n = c.instrument.detector_px;
    let mut stars = 0;
    for e in &exp.arrays {
        for t in &e.truth {
            let i = t.y_px.round() as usize * n + t.x_px.round() as usize;
            assert!(
                e.image.dq[i] & dq::SATURATED != 0,
                "star {} at Hw {}",
                t.id,
                t.mag_hw
            );
            // the well clips the electrons; the read noise (after it) scatters the value by σ_read
            let g = c.detector.gain_e_per_adu;
            let full = c.detector.full_well_e / g + c.detector.bias_adu;
            let read = 6.0 * c.detector.image_read_noise_e() / g;
            assert!(
                (e.image.adu[i] as f64 - full).abs() <= read,
                "clipped at the full well: {} ADU",
                e.image.adu[i]
            );
            stars += 1;
        }
    }
    assert!(stars >= 5, "{stars} stars");
}

#[test]
fn a_sky_catalogue_in_2mass_magnitudes_and_fits_is_read_alike() {
    // j, h → Hw by SPEC §5, a_hw added; a FITS table with the same columns gives the same stars
    let dir = temp_dir("fp-2mass");
    let csv = dir.join("stars.csv");
    std::fs::write(
        &csv,
        "RA,Dec,J,H,a_hw\n266.41,-29.0,14.0,12.0,0.5\n266.42,-29.01,15.5,13.0,0\n",
    )
    .expect("write");
    let stars = match scene::catalogue::read(&csv, 12.5, 2.0, 512.0).expect("read") {
        scene::catalogue::Catalogue::Sky(s) => s,
        other => panic!("{other:?}"),
    };
    let hw = |j: f64, h: f64| {
        let c = j - h;
        h + 1.08 * c - 0.15 * c * c + 0.01 * c * c * c
    };
    assert!((stars[0].mag_hw - (hw(14.0, 12.0) + 0.5)).abs() < 1e-12);
    assert!((stars[1].mag_hw - hw(15.5, 13.0)).abs() < 1e-12);
    assert_eq!((stars[0].j_minus_h, stars[1].j_minus_h), (2.0, 2.5));
    let fits_path = dir.join("stars.fits");
    let col = |name: &str, v: &[f64]| engine::io::fits::Column::F64(name.into(), v.to_vec());
    engine::io::fits::write(
        &fits_path,
        &[
            engine::io::fits::Hdu::Header { cards: vec![] },
            engine::io::fits::Hdu::Table {
                name: "STARS",
                columns: vec![
                    col("ra", &[266.41, 266.42]),
                    col("dec", &[-29.0, -29.01]),
                    col("j", &[14.0, 15.5]),
                    col("h", &[12.0, 13.0]),
                    col("a_hw", &[0.5, 0.0]),
                ],
                cards: vec![],
            },
        ],
    )
    .expect("fits catalogue");
    match scene::catalogue::read(&fits_path, 12.5, 2.0, 512.0).expect("read fits") {
        scene::catalogue::Catalogue::Sky(f) => assert_eq!(f, stars),
        other => panic!("{other:?}"),
    }
    // a row far outside the allowed range is an error naming the line and column
    std::fs::write(&csv, "ra,dec,hw\n266.4,-29.0,12\n400,-29.0,12\n").expect("write");
    let e = scene::catalogue::read(&csv, 12.5, 2.0, 512.0).expect_err("ra 400");
    assert!(
        e.to_string().contains("line 3") && e.to_string().contains("column ra"),
        "{e}"
    );
    // a pixel catalogue cannot fill the quad
    std::fs::write(&csv, "x,y,hw\n10,10,12\n").expect("write");
    let mut c = quad();
    c.scene.kind = SceneKind::Catalogue;
    c.scene.catalogue = Some(csv);
    let e = FocalPlaneSimulator::new(&c)
        .err()
        .expect("pixels on a quad");
    assert!(e.to_string().contains("ra, dec"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
