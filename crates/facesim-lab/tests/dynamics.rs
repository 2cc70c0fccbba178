//! The block-and-needle benchmark of Alterovitz & Goldberg 2003.

use facesim_lab::dynamics::{
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
    let runs: Vec<_> = Integrator::ALL
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
    let mean = |r: &facesim_lab::dynamics::Run| {
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

#[test]
fn the_rod_under_gravity_settles_to_the_static_deflection_in_every_integrator() {
    use facesim_lab::dynamics::MP3;
    let rod = Block::rod(2, 4, 2, MP3, 0.05);
    let steps = 900; // 30 s at h = 1/30
    let runs: Vec<_> = Integrator::ALL
        .into_iter()
        .map(|i| integrate(&rod, i, H, steps, RAYLEIGH))
        .collect();
    let static_end = runs[3].history.last().unwrap();
    let tip = static_end.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    println!(
        "MP3 rod: static tip deflection {tip:.4e} m; explicit consistent h_crit {:.4e} s, lumped {:.4e} s",
        critical_step(&rod, false),
        critical_step(&rod, true)
    );
    // Euler–Bernoulli cantilever under self-weight: δ = q L⁴ / (8 E I), q = ρ g A. The rod is
    // stubby (L/h = 2) and the mesh coarse, so shear and discretisation move the FE value by a
    // few per cent; the check is that gravity, mass and stiffness are assembled at the right scale.
    let (q, l, i) = (MP3.rho * 0.05 * 0.25 * 0.25, 0.5f64, 0.25f64.powi(4) / 12.0);
    let beam = q * l.powi(4) / (8.0 * MP3.e * i);
    println!(
        "Euler–Bernoulli tip deflection {beam:.4e} m (FE / beam = {:.3})",
        tip / beam
    );
    assert!((tip / beam - 1.0).abs() < 0.2);
    for r in &runs {
        match &r.diverged {
            Some(d) => println!("{:?}: {d}", r.integrator),
            None => {
                let e = relative_energy_error(&rod, r.history.last().unwrap(), static_end);
                println!(
                    "{:?}: final vs static, relative energy norm {e:.2e}",
                    r.integrator
                );
                assert!(e < 1e-3, "{:?}", r.integrator);
            }
        }
    }
    assert!(
        runs[0].diverged.is_none(),
        "the implicit reference must not diverge"
    );
}
