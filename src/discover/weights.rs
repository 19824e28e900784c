//! The noise model of a discovery at a state: the measured components from
//! [`crate::noise`], the whitened problem they give, and the noise floor in millimetres.

use super::*;

/// Per-row pose sensitivity to each joint's torque, `∂pose/∂τ_j` (6 × 6).
pub(super) fn torque_sensitivity(
    state: &EffectState,
    geom: &Model,
    o: &Obs,
) -> nalgebra::Matrix6<f64> {
    let q = forward::link_angles(state, o);
    let mut j = geom.jacobian(&q);
    for k in 0..6 {
        let c = state.compliance[k];
        // dδ/dτ: the inverse of the spring's tangent stiffness at its deflection
        let dd = if state.kcub[k] > 0.0 && c > 0.0 {
            let s = crate::model::Stiffness {
                klin: 1.0 / c,
                kcub: state.kcub[k],
            };
            1.0 / s.tangent(s.deflection(o.tau[k]))
        } else {
            c
        };
        for r in 0..6 {
            j[(r, k)] *= dd;
        }
    }
    j
}

/// The noise model at `state`, estimated from the data by [`crate::noise`] (reading noise,
/// repeatable resolver error, instrument and torque noise), and the whitened problem. The
/// repeatable error used for whitening is the estimate capped at the resolver's specified σ:
/// between-configuration variance beyond the specification is lack of fit, not noise (an
/// uncapped estimate would absorb any missing effect of the configuration).
pub(super) fn problem(
    lay: &Layout,
    state: &EffectState,
    n_params: usize,
) -> Result<(Problem, NoiseReport), DiscoverError> {
    let geom = state.geometry()?;
    let sens: Vec<nalgebra::Matrix6<f64>> = lay
        .obs
        .iter()
        .map(|o| torque_sensitivity(state, &geom, o))
        .collect();
    let jac: Vec<nalgebra::Matrix6<f64>> = lay
        .obs
        .iter()
        .map(|o| geom.jacobian(&forward::link_angles(state, o)))
        .collect();
    let mut samples = Vec::new();
    let mut cell_id = 0usize;
    let mut train_blocks = 0usize;
    for (b, layout::ConfigRows { train, cells, .. }) in lay.blocks.iter().enumerate() {
        if !train {
            continue;
        }
        train_blocks += 1;
        for c in cells {
            for &i in c {
                let o = &lay.obs[i];
                samples.push(crate::noise::Sample {
                    config: b,
                    cell: cell_id,
                    q: o.q,
                    tau: o.tau,
                    // The estimator takes measured − predicted and ∂pred/∂τ; discovery's
                    // residuals are predicted − measured and its sensitivity ∂r/∂τ.
                    residual: -forward::residual(state, &geom, o),
                    jq: jac[i],
                    jt: -sens[i],
                });
            }
            cell_id += 1;
        }
    }
    let prior = crate::noise::Prior {
        position_m: lay.meta_position_m.unwrap_or(12.1e-6),
        resolver_rad: lay.resolver_arcmin * crate::accuracy::ARCMIN,
    };
    let between_dof = (6 * train_blocks) as f64 - n_params as f64;
    let rot = *geom.base_from_instrument().rotation.matrix();
    let model = crate::noise::estimate(&samples, &rot, between_dof.max(1.0), &prior)?;
    let repeatable_used = model.repeatable_rad.value.min(prior.resolver_rad);
    let d: Vec<nalgebra::Matrix6<f64>> = lay
        .obs
        .iter()
        .enumerate()
        .map(|(i, o)| model.row_covariance(&jac[i], &sens[i], &o.tau))
        .collect();
    let p = Problem::new(
        lay.obs.clone(),
        lay.blocks.clone(),
        &d,
        state,
        &geom,
        repeatable_used,
    );
    Ok((
        p,
        NoiseReport {
            repeatable_used_rad: repeatable_used,
            model,
        },
    ))
}

/// Expected held-out RMS position error from resolver, instrument and torque noise, mm.
pub(super) fn noise_floor_mm(
    p: &Problem,
    state: &EffectState,
    geom: &Model,
    folds: &[Vec<usize>],
    sr: f64,
) -> f64 {
    let (mut ss, mut n) = (0.0, 0usize);
    // over the rows the held-out gap is measured on
    let counts = super::heldout::in_gap(p, folds);
    for &b in folds.iter().flatten().filter(|&&b| counts(b)) {
        for &i in &p.blocks[b].rows {
            let q = forward::link_angles(state, &p.obs[i]);
            let j = geom.jacobian(&q);
            let d = &p.d[i];
            ss += j.fixed_rows::<3>(0).norm_squared() * sr * sr + d[(0, 0)] + d[(1, 1)] + d[(2, 2)];
            n += 1;
        }
    }
    (ss / n.max(1) as f64).sqrt() * 1e3
}
