//! [`Config::validate`]: every field checked, the error naming the field and the allowed range.

use super::{AceCase, Config, ConfigError, IntraPixel, Sampling, SceneKind, invalid};

/// Largest ACE σ accepted, mas.
pub const MAX_ACE_SIGMA_MAS: f64 = 1.0e4;

fn check_finite(field: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(invalid(field, v, "must be a finite number"))
    }
}
fn check_pos(field: &str, v: f64) -> Result<(), ConfigError> {
    check_finite(field, v)?;
    if v > 0.0 {
        Ok(())
    } else {
        Err(invalid(field, v, "must be > 0"))
    }
}
fn check_nonneg(field: &str, v: f64) -> Result<(), ConfigError> {
    check_finite(field, v)?;
    if v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(field, v, "must be ≥ 0"))
    }
}
fn check_range_usize(field: &str, v: usize, lo: usize, hi: usize) -> Result<(), ConfigError> {
    if (lo..=hi).contains(&v) {
        Ok(())
    } else {
        Err(invalid(field, v, &format!("must be in {lo}..={hi}")))
    }
}

impl Config {
    /// Check every field; the error names the field and the allowed range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.as_built.validate()?;
        self.check_instrument()?;
        self.check_band()?;
        self.check_optics()?;
        self.check_detector()?;
        self.check_readout()?;
        self.check_ace()?;
        self.check_detector_effects()?;
        self.check_sky()?;
        self.check_observation()?;
        self.check_focal_plane()?;
        self.check_scene()?;
        self.check_fidelity()?;
        self.check_analysis()?;
        Ok(())
    }

    /// `[instrument]`: each field in its range.
    fn check_instrument(&self) -> Result<(), ConfigError> {
        let i = &self.instrument;
        check_pos("instrument.aperture_diameter_m", i.aperture_diameter_m)?;
        check_nonneg(
            "instrument.obstruction_diameter_m",
            i.obstruction_diameter_m,
        )?;
        if i.obstruction_diameter_m >= i.aperture_diameter_m {
            return Err(invalid(
                "instrument.obstruction_diameter_m",
                i.obstruction_diameter_m,
                &format!(
                    "must be smaller than instrument.aperture_diameter_m = {}",
                    i.aperture_diameter_m
                ),
            ));
        }
        check_nonneg("instrument.spider_width_m", i.spider_width_m)?;
        if i.spider_width_m >= i.aperture_diameter_m {
            return Err(invalid(
                "instrument.spider_width_m",
                i.spider_width_m,
                &format!(
                    "must be narrower than the aperture ({} m)",
                    i.aperture_diameter_m
                ),
            ));
        }
        if i.spider_count > 64 {
            return Err(invalid(
                "instrument.spider_count",
                i.spider_count,
                "must be in 0..=64",
            ));
        }
        check_finite("instrument.spider_angle_deg", i.spider_angle_deg)?;
        check_pos("instrument.focal_length_m", i.focal_length_m)?;
        check_pos("instrument.pixel_pitch_um", i.pixel_pitch_um)?;
        check_range_usize("instrument.detector_px", i.detector_px, 8, 65_536)?;
        if i.photosensitive_px > i.detector_px || i.photosensitive_px == 0 {
            return Err(invalid(
                "instrument.photosensitive_px",
                i.photosensitive_px,
                &format!("must be in 1..={} (instrument.detector_px)", i.detector_px),
            ));
        }
        Ok(())
    }
    /// `[band]`: each field in its range.
    fn check_band(&self) -> Result<(), ConfigError> {
        let b = &self.band;
        check_pos("band.wavelength_min_um", b.wavelength_min_um)?;
        check_pos("band.wavelength_max_um", b.wavelength_max_um)?;
        check_pos("band.wavelength_step_um", b.wavelength_step_um)?;
        if b.wavelength_max_um < b.wavelength_min_um {
            return Err(invalid(
                "band.wavelength_max_um",
                b.wavelength_max_um,
                "must be ≥ band.wavelength_min_um",
            ));
        }
        if (b.wavelength_max_um - b.wavelength_min_um) / b.wavelength_step_um > 10_000.0 {
            return Err(invalid(
                "band.wavelength_step_um",
                b.wavelength_step_um,
                "gives more than 10000 wavelengths",
            ));
        }
        for (k, p) in b.response.iter().enumerate() {
            check_nonneg(&format!("band.response[{k}]"), p[1])?;
            check_pos(&format!("band.response[{k}]"), p[0])?;
            if k > 0 && p[0] < b.response[k - 1][0] {
                return Err(invalid(
                    &format!("band.response[{k}]"),
                    p[0],
                    "wavelengths must increase",
                ));
            }
        }
        if b.wavelength_grid().is_empty() {
            return Err(invalid(
                "band",
                format!("{}–{} µm", b.wavelength_min_um, b.wavelength_max_um),
                "the wavelength grid has no point where throughput × QE > 0",
            ));
        }
        Ok(())
    }
    /// `[optics]`: each field in its range.
    fn check_optics(&self) -> Result<(), ConfigError> {
        let o = &self.optics;
        check_range_usize("optics.pupil_samples", o.pupil_samples, 16, 4096)?;
        check_range_usize("optics.psf_oversampling", o.psf_oversampling, 1, 64)?;
        check_range_usize("optics.psf_radius_px", o.psf_radius_px, 2, 256)?;
        check_pos("optics.reference_wavelength_um", o.reference_wavelength_um)?;
        if o.fringe.len() > 37 {
            return Err(invalid(
                "optics.fringe",
                o.fringe.len(),
                "at most 37 Fringe Zernike terms",
            ));
        }
        for (k, c) in o.fringe.iter().enumerate() {
            check_finite(&format!("optics.fringe[{k}]"), *c)?;
        }
        for (t, row) in o.field_table.iter().enumerate() {
            check_finite(&format!("optics.field_table[{t}].x_px"), row.x_px)?;
            check_finite(&format!("optics.field_table[{t}].y_px"), row.y_px)?;
            if row.fringe.len() > 37 {
                return Err(invalid(
                    &format!("optics.field_table[{t}].fringe"),
                    row.fringe.len(),
                    "at most 37 terms",
                ));
            }
            for (k, c) in row.fringe.iter().enumerate() {
                check_finite(&format!("optics.field_table[{t}].fringe[{k}]"), *c)?;
            }
        }
        if !o.field_table.is_empty()
            && let Err(why) = super::field_grid_shape(&o.field_table)
        {
            return Err(invalid("optics.field_table", o.field_table.len(), &why));
        }
        check_nonneg("optics.field_wfe_step_nm", o.field_wfe_step_nm)?;
        if o.field_wfe_step_nm > 100.0 {
            return Err(invalid(
                "optics.field_wfe_step_nm",
                o.field_wfe_step_nm,
                "must be ≤ 100 nm",
            ));
        }
        check_range_usize("optics.field_zone_px", o.field_zone_px, 0, 100_000)?;
        Ok(())
    }
    /// `[detector]`: each field in its range.
    fn check_detector(&self) -> Result<(), ConfigError> {
        let d = &self.detector;
        check_pos("detector.exposure_s", d.exposure_s)?;
        if d.exposure_s > 3600.0 {
            return Err(invalid(
                "detector.exposure_s",
                d.exposure_s,
                "must be ≤ 3600 s",
            ));
        }
        check_nonneg("detector.dark_e_per_s", d.dark_e_per_s)?;
        check_nonneg("detector.read_noise_per_read_e", d.read_noise_per_read_e)?;
        if d.read_noise_per_read_e > 1e4 {
            return Err(invalid(
                "detector.read_noise_per_read_e",
                d.read_noise_per_read_e,
                "must be ≤ 10000 e⁻",
            ));
        }
        if let Sampling::Fowler { pairs } = d.sampling
            && !(1..=1024).contains(&pairs)
        {
            return Err(invalid(
                "detector.sampling.fowler.pairs",
                pairs,
                "must be in 1..=1024",
            ));
        }
        check_pos("detector.gain_e_per_adu", d.gain_e_per_adu)?;
        check_pos("detector.full_well_e", d.full_well_e)?;
        if !(1..=32).contains(&d.adc_bits) {
            return Err(invalid(
                "detector.adc_bits",
                d.adc_bits,
                "must be in 1..=32",
            ));
        }
        check_finite("detector.bias_adu", d.bias_adu)?;
        check_nonneg("detector.inter_pixel_flat_sigma", d.inter_pixel_flat_sigma)?;
        if d.inter_pixel_flat_sigma > 0.5 {
            return Err(invalid(
                "detector.inter_pixel_flat_sigma",
                d.inter_pixel_flat_sigma,
                "must be ≤ 0.5",
            ));
        }
        if let IntraPixel::Parabolic { amplitude } = d.intra_pixel
            && !(amplitude.is_finite() && (0.0..0.5).contains(&amplitude))
        {
            return Err(invalid(
                "detector.intra_pixel.amplitude",
                amplitude,
                "allowed 0 ≤ amplitude < 0.5 (the edges' response 1 − 2·amplitude stays positive)",
            ));
        }
        if let IntraPixel::Separable {
            profile_x,
            profile_y,
        } = &d.intra_pixel
        {
            for (name, p) in [("profile_x", profile_x), ("profile_y", profile_y)] {
                if p.is_empty() {
                    return Err(invalid(
                        &format!("detector.intra_pixel.{name}"),
                        "[]",
                        "needs at least one value",
                    ));
                }
                for (k, v) in p.iter().enumerate() {
                    check_nonneg(&format!("detector.intra_pixel.{name}[{k}]"), *v)?;
                }
                if p.iter().sum::<f64>() <= 0.0 {
                    return Err(invalid(
                        &format!("detector.intra_pixel.{name}"),
                        "all zero",
                        "needs a positive mean",
                    ));
                }
            }
        }
        Ok(())
    }
    /// `[readout]`: each field in its range.
    fn check_readout(&self) -> Result<(), ConfigError> {
        let i = &self.instrument;
        let r = &self.readout;
        check_range_usize("readout.channels", r.channels, 1, 1024)?;
        check_range_usize("readout.channel_width_px", r.channel_width_px, 1, 65_536)?;
        if r.channels * r.channel_width_px < i.detector_px {
            return Err(invalid(
                "readout.channel_width_px",
                r.channel_width_px,
                &format!(
                    "channels × width must cover instrument.detector_px = {}",
                    i.detector_px
                ),
            ));
        }
        check_nonneg("readout.pixel_time_us", r.pixel_time_us)?;
        check_nonneg("readout.t_overhead_s", r.t_overhead_s)?;
        check_nonneg("readout.exposure_cadence_s", r.exposure_cadence_s)?;
        Ok(())
    }
    /// `[ace]` and `[photometry]`: each field in its range.
    fn check_ace(&self) -> Result<(), ConfigError> {
        let a = &self.ace;
        check_nonneg("ace.sigma_mas", a.sigma_mas)?;
        // beyond ≈ 20 px rms a star is a streak many times the PSF: no ePSF analysis applies, and the
        // stamps (radius + jitter excursion) grow as σ², so the run time would have no useful bound
        if a.sigma_mas > MAX_ACE_SIGMA_MAS {
            return Err(invalid(
                "ace.sigma_mas",
                a.sigma_mas,
                &format!("must be ≤ {MAX_ACE_SIGMA_MAS} mas (≈ 21 px rms)"),
            ));
        }
        check_pos("ace.boundary_freq_hz", a.boundary_freq_hz)?;
        check_finite("ace.power_law_index", a.power_law_index)?;
        if !(0.0..=8.0).contains(&a.power_law_index) {
            return Err(invalid(
                "ace.power_law_index",
                a.power_law_index,
                "must be in 0..=8",
            ));
        }
        check_nonneg("ace.continuum_amplitude", a.continuum_amplitude)?;
        for (k, m) in a.modes.iter().enumerate() {
            check_pos(&format!("ace.modes[{k}].freq_hz"), m.freq_hz)?;
            check_pos(&format!("ace.modes[{k}].width_hz"), m.width_hz)?;
            check_nonneg(&format!("ace.modes[{k}].amplitude"), m.amplitude)?;
        }
        check_nonneg("ace.amplitude_noise", a.amplitude_noise)?;
        check_pos("ace.sample_interval_ms", a.sample_interval_ms)?;
        check_pos("ace.span_s", a.span_s)?;
        let n_samples = a.span_s / (a.sample_interval_ms * 1e-3);
        if n_samples > 5.0e7 {
            return Err(invalid(
                "ace.span_s",
                a.span_s,
                "with ace.sample_interval_ms gives more than 5e7 samples",
            ));
        }
        check_nonneg("ace.first_exposure_start_s", a.first_exposure_start_s)?;
        if a.case == AceCase::Realistic {
            let need = a.first_exposure_start_s + self.exposure_cadence_s();
            if need > a.span_s {
                return Err(invalid(
                    "ace.span_s",
                    a.span_s,
                    &format!(
                        "must cover at least one exposure cycle ({need:.3} s from the series start)"
                    ),
                ));
            }
        }

        check_pos(
            "photometry.zero_point_e_per_s",
            self.photometry.zero_point_e_per_s,
        )?;
        Ok(())
    }
    /// `[detector]`'s effects (cosmic rays, inter-pixel capacitance, nonlinearity, persistence): each field in
    /// its range.
    fn check_detector_effects(&self) -> Result<(), ConfigError> {
        let d = &self.detector;
        for (field, v, hi) in [
            (
                "detector.cosmic_ray_rate_per_cm2_s",
                d.cosmic_ray_rate_per_cm2_s,
                1.0e4,
            ),
            ("detector.cosmic_ray_e_per_um", d.cosmic_ray_e_per_um, 1.0e5),
            (
                "detector.absorber_thickness_um",
                d.absorber_thickness_um,
                1.0e3,
            ),
        ] {
            check_nonneg(field, v)?;
            if v > hi {
                return Err(invalid(field, v, &format!("must be ≤ {hi}")));
            }
        }
        for (field, v) in [
            ("detector.ipc_alpha", d.ipc_alpha),
            ("detector.ipc_alpha_diagonal", d.ipc_alpha_diagonal),
        ] {
            check_nonneg(field, v)?;
            if v > 0.1 {
                return Err(invalid(field, v, "must be ≤ 0.1"));
            }
        }
        check_nonneg("detector.nonlinearity_per_e", d.nonlinearity_per_e)?;
        if d.nonlinearity_per_e * d.full_well_e > 0.2 {
            return Err(invalid(
                "detector.nonlinearity_per_e",
                d.nonlinearity_per_e,
                "β × full_well_e must be ≤ 0.2 (a response that turns over is not a detector)",
            ));
        }
        check_finite(
            "detector.nonlinearity_calibration_error",
            d.nonlinearity_calibration_error,
        )?;
        if d.nonlinearity_calibration_error.abs() > 1.0 {
            return Err(invalid(
                "detector.nonlinearity_calibration_error",
                d.nonlinearity_calibration_error,
                "must be in -1 … 1",
            ));
        }
        let p = &d.persistence;
        if p.tau_s.len() != p.rho.len() || p.tau_s.is_empty() || p.tau_s.len() > 16 {
            return Err(invalid(
                "detector.persistence.rho",
                p.rho.len() as f64,
                &format!(
                    "needs one density per time constant (tau_s has {}), 1 … 16 trap populations",
                    p.tau_s.len()
                ),
            ));
        }
        for tau in &p.tau_s {
            check_pos("detector.persistence.tau_s", *tau)?;
            if *tau > 1.0e7 {
                return Err(invalid(
                    "detector.persistence.tau_s",
                    *tau,
                    "must be ≤ 1e7 s",
                ));
            }
        }
        for rho in &p.rho {
            check_nonneg("detector.persistence.rho", *rho)?;
        }
        let rho_sum: f64 = p.rho.iter().sum();
        if rho_sum > 0.1 {
            return Err(invalid(
                "detector.persistence.rho",
                rho_sum,
                "the densities must sum to ≤ 0.1 (a tenth of the charge trapped)",
            ));
        }
        check_nonneg("detector.persistence.threshold_e", p.threshold_e)?;
        check_nonneg("detector.persistence.lookback_s", p.lookback_s)?;
        if p.lookback_s > 86_400.0 {
            return Err(invalid(
                "detector.persistence.lookback_s",
                p.lookback_s,
                "must be ≤ 86400 s (a day)",
            ));
        }
        if d.absorber_thickness_um <= 0.0 {
            return Err(invalid(
                "detector.absorber_thickness_um",
                d.absorber_thickness_um,
                "must be > 0",
            ));
        }
        Ok(())
    }
    /// `[sky]`: each field in its range.
    fn check_sky(&self) -> Result<(), ConfigError> {
        let sky = &self.sky;
        if !(sky.ra_deg >= 0.0 && sky.ra_deg < 360.0) {
            return Err(invalid(
                "sky.ra_deg",
                sky.ra_deg,
                "must be in [0, 360) degrees",
            ));
        }
        if !(-90.0..=90.0).contains(&sky.dec_deg) {
            return Err(invalid(
                "sky.dec_deg",
                sky.dec_deg,
                "must be in -90..=90 degrees",
            ));
        }
        check_finite("sky.pa_deg", sky.pa_deg)?;
        Ok(())
    }
    /// `[observation]`: each field in its range.
    fn check_observation(&self) -> Result<(), ConfigError> {
        let obs = &self.observation;
        crate::time::Epoch::from_utc_iso(&obs.start_utc)
            .map_err(|why| invalid("observation.start_utc", &obs.start_utc, &why))?;
        if !(1900.0..=2100.0).contains(&obs.catalogue_epoch_jyear) {
            return Err(invalid(
                "observation.catalogue_epoch_jyear",
                obs.catalogue_epoch_jyear,
                "must be in 1900 … 2100 (Julian years)",
            ));
        }
        if !(200.0..=100_000.0).contains(&obs.orbit_altitude_km) {
            return Err(invalid(
                "observation.orbit_altitude_km",
                obs.orbit_altitude_km,
                "must be in 200 … 100000 km",
            ));
        }
        if !(0.0..=24.0).contains(&obs.orbit_ltan_h) {
            return Err(invalid(
                "observation.orbit_ltan_h",
                obs.orbit_ltan_h,
                "must be in 0 … 24 hours",
            ));
        }
        check_finite("observation.orbit_phase_deg", obs.orbit_phase_deg)?;
        Ok(())
    }
    /// `[focal_plane]`: each field in its range.
    fn check_focal_plane(&self) -> Result<(), ConfigError> {
        let fp = &self.focal_plane;
        check_nonneg("focal_plane.gap_px", fp.gap_px)?;
        if fp.gap_px > 10.0 * self.instrument.detector_px as f64 {
            return Err(invalid(
                "focal_plane.gap_px",
                fp.gap_px,
                "must be at most 10 × instrument.detector_px",
            ));
        }
        for (k, r) in fp.rotations_deg.iter().enumerate() {
            if ![0.0, 90.0, 180.0, 270.0].contains(r) {
                return Err(invalid(
                    &format!("focal_plane.rotations_deg[{k}]"),
                    r,
                    "must be 0, 90, 180 or 270",
                ));
            }
        }
        for (k, o) in fp.array_offsets_px.iter().enumerate() {
            if !o
                .iter()
                .all(|v| v.is_finite() && v.abs() <= fp.gap_px / 2.0)
            {
                return Err(invalid(
                    &format!("focal_plane.array_offsets_px[{k}]"),
                    format!("{o:?}"),
                    &format!(
                        "each must be within ±gap_px/2 = ±{} px (arrays may not overlap)",
                        fp.gap_px / 2.0
                    ),
                ));
            }
        }
        for (k, e) in fp.array_rotation_errors_deg.iter().enumerate() {
            if !(e.is_finite() && e.abs() <= 1.0) {
                return Err(invalid(
                    &format!("focal_plane.array_rotation_errors_deg[{k}]"),
                    e,
                    "must be within ±1 degree",
                ));
            }
        }
        for (name, terms) in [
            ("focal_plane.sip_a", &fp.sip_a),
            ("focal_plane.sip_b", &fp.sip_b),
        ] {
            if terms.len() > 64 {
                return Err(invalid(name, terms.len(), "at most 64 terms"));
            }
            for (k, t) in terms.iter().enumerate() {
                if !(2..=9).contains(&(t.p + t.q)) {
                    return Err(invalid(
                        &format!("{name}[{k}]"),
                        format!("p = {}, q = {}", t.p, t.q),
                        "p + q must be 2 … 9 (first-order terms belong to the CD matrix)",
                    ));
                }
                check_finite(&format!("{name}[{k}].value"), t.value)?;
            }
        }
        Ok(())
    }
    /// `[scene]`: each field in its range.
    fn check_scene(&self) -> Result<(), ConfigError> {
        let s = &self.scene;
        check_finite("scene.mag_hw", s.mag_hw)?;
        if !(-5.0..=40.0).contains(&s.mag_hw) {
            return Err(invalid("scene.mag_hw", s.mag_hw, "must be in -5..=40"));
        }
        check_finite("scene.j_minus_h", s.j_minus_h)?;
        if !(-2.0..=8.0).contains(&s.j_minus_h) {
            return Err(invalid("scene.j_minus_h", s.j_minus_h, "must be in -2..=8"));
        }
        check_range_usize("scene.grid_n", s.grid_n, 1, 1000)?;
        check_pos("scene.grid_spacing_px", s.grid_spacing_px)?;
        check_nonneg("scene.grid_random_px", s.grid_random_px)?;
        let b = &s.bulge;
        check_nonneg("scene.bulge.density_per_arcmin2", b.density_per_arcmin2)?;
        if b.density_per_arcmin2 > 1.0e4 {
            return Err(invalid(
                "scene.bulge.density_per_arcmin2",
                b.density_per_arcmin2,
                "must be at most 1e4 stars per arcmin² (ten per pixel)",
            ));
        }
        for (name, v) in [
            ("scene.bulge.hw_min", b.hw_min),
            ("scene.bulge.hw_max", b.hw_max),
            ("scene.bulge.density_hw_limit", b.density_hw_limit),
        ] {
            check_finite(name, v)?;
            if !(-5.0..=35.0).contains(&v) {
                return Err(invalid(name, v, "must be in -5..=35"));
            }
        }
        for (name, v) in [
            ("scene.bulge.hw_max", b.hw_max),
            ("scene.bulge.density_hw_limit", b.density_hw_limit),
        ] {
            if b.hw_min >= v {
                let rule = format!("must be < {name} = {v}");
                return Err(invalid("scene.bulge.hw_min", b.hw_min, &rule));
            }
        }
        check_finite("scene.bulge.lf_slope", b.lf_slope)?;
        if !(-2.0..=2.0).contains(&b.lf_slope) {
            return Err(invalid(
                "scene.bulge.lf_slope",
                b.lf_slope,
                "must be in -2..=2",
            ));
        }
        // the density extrapolated to hw_max along the luminosity function: bounded as the density is
        let drawn = b.drawn_per_arcmin2();
        if drawn > 1.0e4 {
            let rule = format!(
                "draws {drawn:.3e} stars per arcmin² (the density {} to Hw {} extrapolated along the \
                 luminosity function): at most 1e4 are allowed; lower scene.bulge.hw_max or the density",
                b.density_per_arcmin2, b.density_hw_limit
            );
            return Err(invalid("scene.bulge.hw_max", b.hw_max, &rule));
        }
        for (name, v) in [
            ("scene.bulge.jh_mean", b.jh_mean),
            ("scene.bulge.jh_min", b.jh_min),
            ("scene.bulge.jh_max", b.jh_max),
        ] {
            check_finite(name, v)?;
            if !(-1.0..=10.0).contains(&v) {
                return Err(invalid(name, v, "must be in -1..=10"));
            }
        }
        check_nonneg("scene.bulge.jh_sigma", b.jh_sigma)?;
        if !(5.0..=12.0).contains(&b.distance_kpc) {
            return Err(invalid(
                "scene.bulge.distance_kpc",
                b.distance_kpc,
                "must be in 5 … 12 kpc",
            ));
        }
        for (field, v) in [
            ("scene.bulge.distance_sigma_kpc", b.distance_sigma_kpc),
            ("scene.bulge.pm_l_sigma_mas_per_yr", b.pm_l_sigma_mas_per_yr),
            ("scene.bulge.pm_b_sigma_mas_per_yr", b.pm_b_sigma_mas_per_yr),
        ] {
            check_nonneg(field, v)?;
            if v > 100.0 {
                return Err(invalid(field, v, "must be ≤ 100"));
            }
        }
        for (field, v) in [
            ("scene.bulge.pm_l_mean_mas_per_yr", b.pm_l_mean_mas_per_yr),
            ("scene.bulge.pm_b_mean_mas_per_yr", b.pm_b_mean_mas_per_yr),
        ] {
            check_finite(field, v)?;
            if v.abs() > 1000.0 {
                return Err(invalid(field, v, "must be in -1000 … 1000 mas/yr"));
            }
        }
        if b.jh_min > b.jh_max {
            return Err(invalid(
                "scene.bulge.jh_min",
                b.jh_min,
                "must be ≤ scene.bulge.jh_max",
            ));
        }
        if s.kind == SceneKind::Catalogue && s.catalogue.is_none() {
            return Err(invalid(
                "scene.catalogue",
                "missing",
                "a CSV path is needed when scene.kind = \"catalogue\"",
            ));
        }
        Ok(())
    }
    /// `[fidelity]`: each field in its range.
    fn check_fidelity(&self) -> Result<(), ConfigError> {
        let f = &self.fidelity;
        check_range_usize("fidelity.images", f.images, 1, 100_000)?;
        check_range_usize("fidelity.stamp_radius_px", f.stamp_radius_px, 0, 512)?;
        check_range_usize("fidelity.subpixels", f.subpixels, 1, 64)?;
        check_range_usize("fidelity.time_stride", f.time_stride, 1, 1_000_000)?;
        check_range_usize("fidelity.deposit_phases", f.deposit_phases, 0, 64)?;
        check_range_usize("fidelity.halo_radius_px", f.halo_radius_px, 0, 1024)?;
        check_nonneg("fidelity.colour_step_mag", f.colour_step_mag)?;
        if f.colour_step_mag > 1.0 {
            return Err(invalid(
                "fidelity.colour_step_mag",
                f.colour_step_mag,
                "must be in 0..=1 mag",
            ));
        }
        check_nonneg("fidelity.wing_threshold_e", f.wing_threshold_e)?;
        if f.wing_threshold_e > 1.0e6 {
            return Err(invalid(
                "fidelity.wing_threshold_e",
                f.wing_threshold_e,
                "must be in 0..=1e6 e⁻",
            ));
        }
        Ok(())
    }
    /// `[analysis]`: each field in its range.
    fn check_analysis(&self) -> Result<(), ConfigError> {
        let an = &self.analysis;
        check_range_usize("analysis.epsf_oversampling", an.epsf_oversampling, 1, 16)?;
        if let super::FlatField::Calibrated { error } = an.flat_field
            && !(0.0..=0.5).contains(&error)
        {
            return Err(invalid(
                "analysis.flat_field.calibrated.error",
                error,
                "must be a relative error in [0, 0.5]",
            ));
        }
        check_range_usize("analysis.epsf_iterations", an.epsf_iterations, 0, 100)?;
        check_range_usize("analysis.epsf_radius_px", an.epsf_radius_px, 2, 64)?;
        check_pos("analysis.fit_radius_px", an.fit_radius_px)?;
        if an.fit_radius_px > an.epsf_radius_px as f64 - 1.0 {
            return Err(invalid(
                "analysis.fit_radius_px",
                an.fit_radius_px,
                &format!(
                    "must be ≤ analysis.epsf_radius_px − 1 = {}",
                    an.epsf_radius_px as f64 - 1.0
                ),
            ));
        }
        check_range_usize("analysis.epsf_zones", an.epsf_zones, 1, 64)?;
        check_range_usize(
            "analysis.telemetry_model_nodes_per_px",
            an.telemetry_model_nodes_per_px,
            1,
            128,
        )?;
        check_range_usize(
            "analysis.telemetry_deconvolution_iterations",
            an.telemetry_deconvolution_iterations,
            1,
            50,
        )?;
        check_pos("analysis.detect_sigma", an.detect_sigma)?;
        check_pos("analysis.crowded_detect_sigma", an.crowded_detect_sigma)?;
        check_range_usize("analysis.fit_max_iter", an.fit_max_iter, 1, 10_000)?;
        check_pos("analysis.clip_sigma", an.clip_sigma)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn expect_field(text: &str, field: &str) {
        match Config::from_toml_str(text) {
            Err(e) => {
                let msg = e.to_string();
                assert!(msg.contains(field), "error `{msg}` should name `{field}`");
            }
            Ok(_) => panic!("config `{text}` should be rejected"),
        }
    }

    #[test]
    fn bad_values_name_their_field() {
        expect_field("[detector]\nexposure_s = -1.0", "detector.exposure_s");
        expect_field("[detector]\nexposure_s = nan", "detector.exposure_s");
        expect_field(
            "[instrument]\nspider_width_m = 0.5",
            "instrument.spider_width_m",
        );
        expect_field(
            "[instrument]\nobstruction_diameter_m = 0.36",
            "instrument.obstruction_diameter_m",
        );
        expect_field(
            "[band]\nwavelength_min_um = 2.0\nwavelength_max_um = 2.5",
            "band",
        );
        expect_field("[readout]\norder = \"sideways\"", "order");
        expect_field("[ace]\nsigma_mas = inf", "ace.sigma_mas");
        expect_field("[scene]\nmag_hw = nan", "scene.mag_hw");
        expect_field("[fidelity]\nsubpixels = 0", "fidelity.subpixels");
        expect_field("[analysis]\nfit_radius_px = 9.0", "analysis.fit_radius_px");
        expect_field("[ace]\nspan_s = 5.0", "ace.span_s");
        expect_field("unknown_key = 3", "unknown_key");
        expect_field("[scene]\nkind = \"catalogue\"", "scene.catalogue");
    }
}
