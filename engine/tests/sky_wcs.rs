//! The engine's WCS against astropy, an outside tool: `data/astropy_wcs.json` holds astropy's pixel → sky
//! (`WCS.all_pix2world`, TAN and TAN-SIP) for headers built from the documented convention by
//! `data/astropy_wcs.py`. The engine must write the same CRPIX/CRVAL/CD and find the same sky positions to
//! 1 µas; the way back (sky → pixel) must return the pixel to 1e-8 px.

use engine::sky::Pointing;
use engine::sky::wcs::{ArrayWcs, KeyValue, Sip, SipPolynomial};
use serde_json::Value;

fn poly(v: &Value) -> SipPolynomial {
    SipPolynomial {
        terms: v
            .as_array()
            .expect("terms")
            .iter()
            .map(|t| {
                let t = t.as_array().expect("a term");
                (
                    t[0].as_u64().expect("p") as usize,
                    t[1].as_u64().expect("q") as usize,
                    t[2].as_f64().expect("c"),
                )
            })
            .collect(),
    }
}

#[test]
fn pixel_to_sky_agrees_with_astropy_to_a_microarcsecond() {
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/astropy_wcs.json"),
    )
    .expect("the astropy fixture");
    let cases: Vec<Value> = serde_json::from_str(&text).expect("JSON");
    assert_eq!(cases.len(), 3);
    for c in &cases {
        let f = |k: &str| c[k].as_f64().expect(k);
        let pair = |k: &str| [c[k][0].as_f64().expect(k), c[k][1].as_f64().expect(k)];
        let sip = (!c["sip"].is_null()).then(|| Sip {
            a: poly(&c["sip"]["a"]),
            b: poly(&c["sip"]["b"]),
        });
        let naxis = [
            c["naxis"][0].as_u64().expect("naxis") as usize,
            c["naxis"][1].as_u64().expect("naxis") as usize,
        ];
        let w = ArrayWcs::new(
            &Pointing {
                ra_deg: f("ra"),
                dec_deg: f("dec"),
                pa_deg: f("pa"),
            },
            f("rot"),
            472.1,
            pair("axis"),
            naxis,
            sip,
        )
        .expect("the WCS");
        let keys = w.keywords();
        for (k, v) in c["header"].as_object().expect("header") {
            let ours = keys
                .iter()
                .find(|kw| kw.key == *k)
                .unwrap_or_else(|| panic!("{}: no {k}", c["name"]));
            let KeyValue::F(x) = ours.value else {
                panic!("{k} is not a number")
            };
            let want = v.as_f64().expect("a number");
            assert!(
                (x - want).abs() <= 1e-15 * want.abs().max(1e-300),
                "{}: {k} = {x}, astropy's header {want}",
                c["name"]
            );
        }
        for (p, s) in c["pixels"]
            .as_array()
            .expect("pixels")
            .iter()
            .zip(c["sky"].as_array().expect("sky"))
        {
            let (x, y) = (p[0].as_f64().expect("x"), p[1].as_f64().expect("y"));
            let (ra_a, dec_a) = (s[0].as_f64().expect("ra"), s[1].as_f64().expect("dec"));
            let (ra, dec) = w.pixel_to_sky(x, y).expect("a sky position");
            let dra = ((ra - ra_a + 180.0).rem_euclid(360.0) - 180.0) * dec_a.to_radians().cos();
            let err_uas = dra.hypot(dec - dec_a) * 3.6e9;
            assert!(
                err_uas < 1.0,
                "{}: pixel ({x}, {y}): {err_uas:.3} µas from astropy",
                c["name"]
            );
            let (x2, y2) = w.sky_to_pixel(ra_a, dec_a).expect("a pixel");
            assert!(
                (x2 - x).hypot(y2 - y) < 1e-8,
                "{}: astropy's sky position of ({x}, {y}) comes back at ({x2}, {y2})",
                c["name"]
            );
        }
    }
}
