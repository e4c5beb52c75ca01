//! Issue 13: "an overflow is called an overflow, not a degenerate cell", in the element
//! built-ins. Elements whose finite node coordinates are so large that the determinant (6 V,
//! 2 A, det J) overflows f64 used to be reported as degenerate; they are now reported as an
//! overflow with the coordinate magnitude. A genuinely flat element is still degenerate, at
//! any scale.

use topomech_rules::mechanics::{hex_stiffness, tet_stiffness, tri_stiffness};

fn tet(s: f64) -> [[f64; 3]; 4] {
    [[0.0; 3], [s, 0.0, 0.0], [0.0, s, 0.0], [0.0, 0.0, s]]
}

fn hex(s: f64) -> [[f64; 3]; 8] {
    let mut x = [[0.0; 3]; 8];
    for (k, (a, b, c)) in [
        (0., 0., 0.),
        (1., 0., 0.),
        (1., 1., 0.),
        (0., 1., 0.),
        (0., 0., 1.),
        (1., 0., 1.),
        (1., 1., 1.),
        (0., 1., 1.),
    ]
    .into_iter()
    .enumerate()
    {
        x[k] = [a * s, b * s, c * s];
    }
    x
}

#[test]
fn overflowing_elements_are_called_overflows() {
    let e = tet_stiffness(tet(1e200), 1e6, 0.3).unwrap_err().0;
    assert!(
        e.contains("overflows f64") && e.contains("1.000e200"),
        "{e}"
    );
    assert!(!e.contains("degenerate"), "{e}");
    let e = tri_stiffness([[0.0, 0.0], [1e200, 0.0], [0.0, 1e200]], 1e6, 0.3, 1.0)
        .unwrap_err()
        .0;
    assert!(
        e.contains("overflows f64") && !e.contains("degenerate"),
        "{e}"
    );
    let e = hex_stiffness(&hex(1e120), 1e6, 0.3).unwrap_err().0;
    assert!(
        e.contains("overflows f64") && !e.contains("degenerate"),
        "{e}"
    );
}

#[test]
fn non_finite_coordinates_are_named_as_such() {
    let mut x = tet(1.0);
    x[2][1] = f64::NAN;
    let e = tet_stiffness(x, 1e6, 0.3).unwrap_err().0;
    assert!(e.contains("a node coordinate is NaN"), "{e}");
}

#[test]
fn flat_elements_are_still_degenerate_and_sound_ones_still_work() {
    let mut x = tet(1.0);
    x[3] = [0.5, 0.5, 0.0];
    let e = tet_stiffness(x, 1e6, 0.3).unwrap_err().0;
    assert!(e.contains("degenerate tetrahedron"), "{e}");
    // scale 1e50: 6 V = 1e150, the squares 1e100: all finite; the stiffness scales as s
    // (E * V * grad^2 ~ s^3 / s^2), so entries stay finite
    let k = tet_stiffness(tet(1e50), 1e6, 0.3).unwrap();
    assert!(k.data.iter().all(|v| v.is_finite()));
}
