//! The benchmark's hand-written baselines (`benches/baselines`) compute what the engine
//! computes: on a small mesh of each model, from the same deformed start, a few steps of each
//! give the same positions to 1e-9 relative to how far the vertices moved. This is what makes
//! the benchmark's ratios a comparison of one algorithm written twice.

#[path = "../benches/baselines/mod.rs"]
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
