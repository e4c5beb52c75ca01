//! The benchmark's hand-written baselines (`benches/baselines`) compute what the engine
//! computes: on a small mesh of each model, from the same deformed start, a few steps of each
//! give the same positions to 1e-9 relative to how far the vertices moved. This is what makes
//! the benchmark's ratios a comparison of one algorithm written twice.

// the benchmark's module of that name
#[allow(clippy::module_inception)]
#[path = "../../benches/baselines/mod.rs"]
mod baselines;

use baselines::{disagreement, polar3, Model, M3};

fn check(model: Model, target: usize) {
    let (cells, _) = model.cells(target);
    let mut sim = model.simulation(&cells);
    let mut base = model.baseline(&sim);
    let start = sim.vertex_vec3("position").unwrap();
    for _ in 0..8 {
        sim.step().unwrap();
        base.step();
    }
    let (rel, motion) = disagreement(&sim, base.as_ref(), &start);
    assert!(motion > 1e-7, "{model:?}: the vertices move ({motion:e})");
    assert!(
        rel < 1e-9,
        "{model:?}: the baseline is {rel:e} (relative) from the engine after 8 steps"
    );
}

#[test]
fn cloth_baseline_matches_the_engine() {
    check(Model::Cloth, 60);
}

#[test]
fn corotational_baseline_matches_the_engine() {
    check(Model::Corotational, 150);
}

#[test]
fn mass_tensor_baseline_matches_the_engine() {
    check(Model::MassTensor, 150);
}

#[test]
fn neohookean_baseline_matches_the_engine() {
    check(Model::NeoHookean, 150);
}

/// The baseline's polar rotation: a rotation, and the rotation of R S for S symmetric
/// positive definite.
#[test]
fn polar_of_rotation_and_stretch() {
    let (s, c) = 0.7_f64.sin_cos();
    let r: M3 = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
    let st: M3 = [[2.0, 0.3, 0.1], [0.3, 0.5, 0.0], [0.1, 0.0, 1e-3]];
    let mut f = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            f[i][j] = (0..3).map(|k| r[i][k] * st[k][j]).sum();
        }
    }
    for m in [r, f] {
        let p = polar3(&m);
        for i in 0..3 {
            for j in 0..3 {
                assert!((p[i][j] - r[i][j]).abs() < 1e-12, "{p:?}");
            }
        }
    }
}

/// The baseline's polar rotation is the engine's `polar`, bit for bit where Newton's
/// iteration applies (the same operations in the same order), and to 1e-13 where both fall
/// back to their Jacobi SVDs (written independently, they round differently: 1e-13 is a few
/// hundred ulps, far below the 1e-9 the benchmark checks): on rotations times stretches
/// with principal stretches from 0.05 to 3 (so both paths are taken), at scales 1e-30..1e30,
/// and on inverted ones.
#[test]
fn polar_is_the_engines() {
    use topomech_rules::builtins::call;
    use topomech_rules::value::{Mat, Val};
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut unit = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        #[allow(clippy::cast_precision_loss)]
        let u = (state >> 11) as f64 / (1u64 << 53) as f64;
        u
    };
    let (mut newton, mut jacobi) = (0, 0);
    for i in 0..4000 {
        // R = rotation about a random axis, S = Q diag(s) Q^T.
        let mut rot = || {
            let axis = [unit() - 0.5, unit() - 0.5, unit() - 0.5];
            let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
            let [x, y, z] = axis.map(|c| c / n);
            let (s, c) = (6.0 * unit()).sin_cos();
            let k = 1.0 - c;
            [
                [c + x * x * k, x * y * k - z * s, x * z * k + y * s],
                [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
                [z * x * k - y * s, z * y * k + x * s, c + z * z * k],
            ]
        };
        let (r, q) = (rot(), rot());
        let mut s = [
            0.05 + 2.95 * unit(),
            0.05 + 2.95 * unit(),
            0.05 + 2.95 * unit(),
        ];
        if i % 5 == 0 {
            s[2] = -s[2];
        }
        let scale = 10f64.powf(60.0 * unit() - 30.0);
        let mut f: M3 = [[0.0; 3]; 3];
        for a in 0..3 {
            for b in 0..3 {
                f[a][b] = scale
                    * (0..3)
                        .map(|k| (0..3).map(|l| r[a][l] * q[l][k]).sum::<f64>() * s[k] * q[b][k])
                        .sum::<f64>();
            }
        }
        let m = Val::M(Mat {
            rows: 3,
            cols: 3,
            data: f.concat(),
        });
        let Ok(Val::M(e)) = call("polar", &[m]) else {
            panic!("polar failed on {f:?}")
        };
        let p = polar3(&f).concat();
        if baselines::polar3_newton(&f, f.concat().iter().fold(0.0, |a: f64, x| a.max(x.abs())))
            .is_some()
        {
            newton += 1;
            assert_eq!(p, e.data, "Newton: {f:?}");
        } else {
            jacobi += 1;
            let d = p
                .iter()
                .zip(&e.data)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(d <= 1e-13, "Jacobi: {d:e} on {f:?}");
        }
    }
    assert!(
        newton > 1000 && jacobi > 500,
        "{newton} by Newton, {jacobi} by Jacobi"
    );
}
