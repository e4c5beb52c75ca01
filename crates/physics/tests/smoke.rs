use topomech_gmap::generators::{cuboid, grid, BoxElement, GridElement};
use topomech_gmap::mesh::{build, BuildOptions};
use topomech_physics::{Config, ModelSpec, Simulation};

#[test]
fn every_model_runs() {
    for kind in [
        "stretch_elementary",
        "stretch_cumulated",
        "linear_fem",
        "corotational",
        "mass_tensor",
    ] {
        let (g, _) = build(
            &cuboid([2, 1, 1], [2.0, 1.0, 1.0], BoxElement::Tetra),
            &BuildOptions::default(),
        )
        .unwrap();
        let cfg = Config {
            models: vec![ModelSpec {
                kind: kind.into(),
                params: Default::default(),
            }],
            fixed: vec!["x < 1e-9".into()],
            ..Config::default()
        };
        let mut s = Simulation::new(g, cfg).unwrap_or_else(|e| panic!("{kind}: {e}"));
        for _ in 0..5 {
            s.step().unwrap_or_else(|e| panic!("{kind}: {e}"));
        }
        eprintln!(
            "{kind}: m = {} ke = {}",
            s.total_mass().unwrap(),
            s.kinetic_energy().unwrap()
        );
    }
    let (g, _) = build(
        &grid([3, 3], [1.0, 1.0], GridElement::Mixed),
        &BuildOptions::default(),
    )
    .unwrap();
    let cfg = Config {
        models: vec![ModelSpec {
            kind: "stretch_cumulated".into(),
            params: Default::default(),
        }],
        ..Config::default()
    };
    let mut s = Simulation::new(g, cfg).unwrap();
    s.step().unwrap();
    eprintln!("2d: m = {}", s.total_mass().unwrap());
}
