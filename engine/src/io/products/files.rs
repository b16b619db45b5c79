//! Every file jsim writes, by command: the one list of output names. `engine/tests/output_files.rs` runs each
//! command and fails on a file in its output directory that is not declared here for it, and on a declared
//! name that no page of docs/ describes.
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

/// Every file jsim writes into an output directory. (`jsim psf --out FILE` and `jsim ace --out FILE` write the
/// one file they are given.)
#[rustfmt::skip]
pub const OUTPUT_FILES: &[OutputFile] = &[
    // jsim simulate: the images, their truth and the instrument's products
    f("img_{NNN}.fits", &[Simulate], "one array's exposure: image, DQ, TRUTH, CONFIG"),
    f("fp_{NNN}.fits", &[Simulate], "one focal-plane exposure: ARRAY1 … ARRAY4, DQ1 … DQ4, TRUTH, CONFIG"),
    f("truth_{NNN}.csv", &[Simulate], "the TRUTH table of one array's exposure as CSV (scoring's side)"),
    f("telemetry_{NNN}.fits", &[Simulate], "the attitude telemetry product of an exposure"),
    f("flat_cal.fits", &[Simulate], "the calibration flat product"),
    f("psf_model.fits", &[Simulate], "the design model PSF product"),
    f("refcat.csv", &[Simulate], "the reference catalogue product"),
    f("run.json", &[Simulate], "the run's seed, timings and account of the stars"),
    f("config.toml", &[Simulate, Sequence], "the configuration as run"),
    // jsim analyze (and its per-array and per-chip directories)
    f("catalogue.csv", &[Analyze], "the fitted stars"),
    f("epsf.fits", &[Analyze], "the ePSF built from the stars"),
    f("summary.json", &[Analyze], "the analysis' report"),
    f("vectors.csv", &[Analyze], "the deviation vector map's data"),
    f("vectors.png", &[Analyze], "the deviation vector map"),
    f("crowded_bins.csv", &[Analyze, Crowded], "accuracy and completeness per bin of true Hw"),
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
    f("repeatability.csv", &[Analyze], "repeatability against the bound, exposures of one pointing"),
    // jsim score
    f("score.csv", &[Score], "completeness and accuracy per bin of true magnitude"),
    f("score.json", &[Score], "the same, the false detections, the common offset, the frame"),
    // jsim experiment
    f("experiment.csv", &[Experiment], "accuracy per case, countermeasure and magnitude"),
    f("images.csv", &[Experiment], "per image: accuracy, bound, timings"),
    f("accuracy.png", &[Experiment], "accuracy against magnitude"),
    f("vectors_{<ace>_<readout>_<mag>}.png", &[Experiment], "the vector map of the first magnitude"),
    f("vectors_{<ace>_<readout>_<mag>}.csv", &[Experiment], "its data"),
    // jsim crowded
    f("crowded_arrays.csv", &[Crowded], "per case and array: detections, ePSF, groups, time"),
    f("stars_{<case>}.csv", &[Crowded], "every reported star of a case"),
    f("accuracy_vs_mag.png", &[Crowded], "accuracy against magnitude per case"),
    f("vectors_{<case>_<countermeasure>}.png", &[Crowded], "the four arrays' vector maps"),
    f("{<case>}/fp_000.fits", &[Crowded], "with --save-images: the case's exposure"),
    f("{<case>}/flat_cal.fits", &[Crowded], "with --save-images: its calibration flat"),
    f("{<case>}/psf_model.fits", &[Crowded], "with --save-images: its design model PSF"),
    f("{<case>}/refcat.csv", &[Crowded], "with --save-images: its reference catalogue"),
    f("{<case>}/telemetry_000.fits", &[Crowded], "with --save-images: its telemetry (a moving ACE)"),
    // jsim sequence
    f("sequence.toml", &[Sequence], "the sequence's spec as run"),
    f("design.toml", &[Sequence], "the design configuration the solution reads"),
    f("sequence.json", &[Sequence], "the plan's summary"),
    f("plan.csv", &[Sequence], "every planned exposure"),
    f("plan_truth.csv", &[Sequence], "each exposure's true pointing (scoring's side)"),
    f("coverage.csv", &[Sequence], "exposures per sky cell"),
    f("coverage.png", &[Sequence], "the coverage map"),
    f("field.csv", &[Sequence], "the field's stars (scoring's side)"),
    f("field_bright.csv", &[Sequence], "with persistence: the stars bright enough to fill traps"),
    f("reference.csv", &[Sequence], "the survey's reference catalogue"),
    f("exposures/{NNNNN}.csv", &[Sequence], "one exposure's catalogue"),
    f("exposures/{NNNNN}_truth.csv", &[Sequence], "one exposure's truth (scoring's side)"),
    f("exposures/fp_{NNNNN}.fits", &[Sequence], "with --keep-images: one exposure's image"),
    f("catalogue.fits", &[Sequence], "every exposure's catalogue gathered"),
    f("slurm/array.sbatch", &[Sequence, Sweep], "with --emit-slurm: the job array"),
    f("slurm/gather.sbatch", &[Sequence], "with --emit-slurm: the gathering job"),
    f("slurm/submit.sh", &[Sequence, Sweep], "with --emit-slurm: submits the jobs in order"),
    // jsim solve (its output directory, default solution/ in the sequence's) and jsim solve-synthetic
    f("sources.csv", &[Solve, SolveSynthetic], "each source's solved astrometry"),
    f("attitudes.csv", &[Solve, SolveSynthetic], "each exposure's solved attitude"),
    f("calibration.csv", &[Solve], "the solved calibration terms"),
    f("calibration_map.csv", &[Solve], "the solved distortion on a grid"),
    f("score_sources.csv", &[Solve], "the sources against the truth (scoring)"),
    f("score_attitudes.csv", &[Solve], "the attitudes against the truth (scoring)"),
    f("precision_vs_n.csv", &[Solve], "the precision against the number of exposures"),
    f("precision_vs_n.png", &[Solve], "its figure"),
    f("mission_budget.csv", &[Solve], "the mission's error budget from the measured precision"),
    f("solution.json", &[Solve, SolveSynthetic], "the solution's report"),
    f("slurm/solve.sbatch", &[Solve], "with --emit-slurm, in the sequence's directory: the MPI job"),
    f("slurm/submit-solve.sh", &[Solve], "with --emit-slurm, in the sequence's directory: submits it"),
    // jsim transit
    f("lightcurve.ecsv", &[Transit], "the differential light curve"),
    f("lightcurve.png", &[Transit], "its figure"),
    f("truth.ecsv", &[Transit], "the injected transit and the true jitter (scoring's side)"),
    f("transit.json", &[Transit], "the stare, its precision, budget and recovery"),
    f("windows.fits", &[Transit], "with --write-products: every window of every plate"),
    f("telemetry.ecsv", &[Transit], "with --write-products: the attitude per plate"),
    f("precision.csv", &[Transit], "with --magnitudes: the precision against magnitude"),
    f("precision.json", &[Transit], "with --magnitudes: the same as JSON"),
    f("precision.png", &[Transit], "with --magnitudes: its figure"),
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
    f("sweep.json", &[Sweep], "the sweep's spec and its points"),
    f("points.csv", &[Sweep], "the grid's points"),
    f("points/point-{NNN}.toml", &[Sweep], "each point's configuration"),
    f("shards/shard-{NNNN}-of-{NNNN}.csv", &[Sweep], "one shard's rows"),
    f("shards/shard-{NNNN}-of-{NNNN}.json", &[Sweep], "one shard's state"),
    f("shards/shard-{NNNN}-of-{NNNN}.lock", &[Sweep], "one shard's lock"),
    f("slurm/merge.sbatch", &[Sweep], "with --emit-slurm: the merging job"),
    f("merged.csv", &[Merge], "every unit's row"),
    f("merged.json", &[Merge], "the merge's diagnostics"),
    f("report.csv", &[Report], "the fraction meeting the threshold per point"),
    f("report/fraction.png", &[Report], "the fractions against the grid"),
    f("report/dist_{p<point>_<countermeasure>}.png", &[Report], "each point's distribution"),
    // jsim bench
    f("bench.csv", &[Bench], "time and error of each knob"),
    f("bench.png", &[Bench], "its figure"),
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
    fn every_pattern_is_declared_once_per_command() {
        for (i, a) in OUTPUT_FILES.iter().enumerate() {
            for b in &OUTPUT_FILES[i + 1..] {
                let shared = a.by.iter().any(|c| b.by.contains(c));
                assert!(!(shared && a.pattern == b.pattern), "{}", a.pattern);
            }
        }
    }
}
