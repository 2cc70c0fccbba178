//! The block-and-needle benchmark of Alterovitz & Goldberg 2003 (issue 5, first part).

use facesim::dynamics::{
    Block, Integrator, MP1, MP2, critical_step, integrate, relative_energy_error,
};

const H: f64 = 1.0 / 30.0;
const RAYLEIGH: (f64, f64) = (1.0, 0.1);

#[test]
fn explicit_integration_of_mp2_at_a_thirtieth_of_a_second_diverges_and_says_so() {
    let b = Block::new(8, MP2);
    for integ in [Integrator::ExplicitConsistent, Integrator::ExplicitLumped] {
        let r = integrate(&b, integ, H, 120, RAYLEIGH);
        println!(
            "{integ:?} MP2 h = 1/30: {:?} after {} finite steps",
            r.diverged,
            r.history.len()
        );
        assert!(
            r.diverged
                .as_deref()
                .is_some_and(|d| d.starts_with("diverged at step"))
        );
        assert!(
            r.history.iter().flatten().all(|x| x.is_finite()),
            "no NaN in the output"
        );
    }
    // The implicit reference stays bounded on the same problem.
    let r = integrate(&b, Integrator::ImplicitNewmark, H, 120, RAYLEIGH);
    assert!(r.diverged.is_none() && r.history.iter().flatten().all(|x| x.abs() < 1.0));
}

#[test]
fn explicit_is_bounded_below_the_critical_step_and_diverges_above_it() {
    let b = Block::new(6, MP2);
    for lumped in [true, false] {
        let hc = critical_step(&b, lumped);
        let integ = if lumped {
            Integrator::ExplicitLumped
        } else {
            Integrator::ExplicitConsistent
        };
        let steps = 3000;
        let below = integrate(&b, integ, 0.9 * hc, steps, (0.0, 0.0));
        let above = integrate(&b, integ, 1.1 * hc, steps, (0.0, 0.0));
        let peak = below
            .history
            .iter()
            .flatten()
            .fold(0.0f64, |m, x| m.max(x.abs()));
        println!(
            "{integ:?}: h_crit = {hc:.4e} s; 0.9 h_crit: peak |u| {peak:.3} m over {steps} steps; 1.1 h_crit: {:?}",
            above.diverged
        );
        assert!(below.diverged.is_none() && peak < 1.0);
        assert!(above.diverged.is_some());
    }
}

#[test]
fn all_integrators_settle_to_the_same_static_state_and_explicit_consistent_is_closest() {
    let b = Block::new(8, MP1);
    let steps = 600; // 20 s: 2 s of needle motion, then settling
    let runs: Vec<_> = [
        Integrator::ImplicitNewmark,
        Integrator::ExplicitConsistent,
        Integrator::ExplicitLumped,
        Integrator::QuasiStatic,
    ]
    .into_iter()
    .map(|i| integrate(&b, i, H, steps, RAYLEIGH))
    .collect();
    for r in &runs {
        assert!(r.diverged.is_none(), "{:?}: {:?}", r.integrator, r.diverged);
    }
    let static_end = runs[3].history.last().unwrap();
    for r in &runs {
        let e = relative_energy_error(&b, r.history.last().unwrap(), static_end);
        println!(
            "{:?}: final state vs static, relative energy norm {e:.2e}",
            r.integrator
        );
        assert!(e < 1e-3);
    }
    // Mean relative energy error against the implicit reference over the motion (first 2 s).
    let mean = |r: &facesim::dynamics::Run| {
        (1..60)
            .map(|s| relative_energy_error(&b, &r.history[s], &runs[0].history[s]))
            .sum::<f64>()
            / 59.0
    };
    let (ec, el, eq) = (mean(&runs[1]), mean(&runs[2]), mean(&runs[3]));
    println!(
        "mean error vs implicit over 2 s: explicit consistent {ec:.3e}, explicit lumped {el:.3e}, quasi-static {eq:.3e}"
    );
    assert!(ec < el && el < eq, "ordering {ec} < {el} < {eq}");
}

#[test]
fn mp1_and_mp2_steady_states_differ() {
    // Different Poisson ratios deform the block differently under the same needle motion.
    let s1 = integrate(
        &Block::new(8, MP1),
        Integrator::QuasiStatic,
        H,
        60,
        RAYLEIGH,
    );
    let s2 = integrate(
        &Block::new(8, MP2),
        Integrator::QuasiStatic,
        H,
        60,
        RAYLEIGH,
    );
    let b = Block::new(8, MP1);
    let e = relative_energy_error(&b, s2.history.last().unwrap(), s1.history.last().unwrap());
    println!("MP2 vs MP1 steady state: relative energy difference {e:.3}");
    assert!(e > 0.05);
}
