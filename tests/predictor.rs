//! The instant predictor against full simulations (the paper's cases on the reduced scene): predicted and
//! measured accuracy agree within 2 standard errors or 15 %.

mod common;

use common::small_config;
use engine::analysis::countermeasures::Plan;
use engine::config::{AceCase, ReadoutOrder};
use engine::session::Session;
use engine::studies::experiment::run_dataset;

#[test]
fn predictor_agrees_with_simulations() {
    let plan = Plan::new(vec![
        "none".parse().expect("none"),
        "plate-poly:3".parse().expect("plate"),
    ])
    .expect("plan");
    let session = Session::new();
    let mut worst: f64 = 0.0;
    for (ace, readout) in [
        (AceCase::Gaussian, ReadoutOrder::Rolling),
        (AceCase::Realistic, ReadoutOrder::Rolling),
        (AceCase::Realistic, ReadoutOrder::SampleHold),
    ] {
        for mag in [12.0, 13.5, 14.5] {
            let mut c = small_config();
            c.ace.case = ace;
            c.readout.order = readout;
            c.scene.mag_hw = mag;
            c.fidelity.images = 4;
            let sim = session.new_simulator(&c).expect("simulator");
            let (rows, _) = run_dataset(&sim, &plan, &mut |_| std::ops::ControlFlow::Continue(()))
                .expect("dataset");
            for r in rows {
                let tol = (2.0 * r.sem_mas).max(0.15 * r.accuracy_mas);
                let miss = (r.predicted_mas - r.accuracy_mas).abs();
                eprintln!(
                    "{:?} {:?} {} Hw {mag}: measured {:.2} ± {:.2}, predicted {:.2} mas",
                    ace, readout, r.countermeasure, r.accuracy_mas, r.sem_mas, r.predicted_mas
                );
                worst = worst.max(miss / tol);
                assert!(
                    miss <= tol,
                    "{ace:?} {readout:?} {} Hw {mag}: measured {} ± {}, predicted {}",
                    r.countermeasure,
                    r.accuracy_mas,
                    r.sem_mas,
                    r.predicted_mas
                );
            }
        }
    }
    eprintln!("worst |predicted − measured| / tolerance = {worst:.2}");
}
