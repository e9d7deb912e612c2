//! The ARAP solver: monotone energy, exact answers for identity and rigid
//! motions, meshes with holes, and errors.
#![allow(clippy::unwrap_used)]

mod common;

use common::{max_diff, space_on, unit_blob};
use mfm_deform::rigid::{axis_angle_to_matrix, mat_vec};
use mfm_deform::{
    Arap, ArapOptions, DeformError, DeformParams, Handle, HandleSet, RigidParams, normalize_rest,
};
use mfm_geometry::{Topology, TriMesh, procedural};
use mfm_processing::holes::{HoleMetric, punch_holes};
use proptest::prelude::*;

#[test]
fn identity_params_return_the_rest_shape() {
    let mesh = unit_blob(3);
    let space = space_on(&mesh);
    let arap = Arap::new(&mesh, &space.handles).unwrap();
    let out = arap
        .deform(&DeformParams::identity(3), &ArapOptions::default())
        .unwrap();
    let err = max_diff(&out.positions, mesh.positions());
    assert!(err < 1e-12, "identity moved the rest shape by {err}");
    assert!(
        out.energies.iter().all(|&e| e.abs() < 1e-24),
        "{:?}",
        out.energies
    );
    assert!(
        arap.energy(mesh.positions(), &ArapOptions::default())
            .unwrap()
            .abs()
            < 1e-28
    );
}

/// A mesh refined on one half has edges whose cotangent weight is negative
/// (two opposite angles over 180 degrees where fine faces meet coarse ones).
/// With those weights the ARAP energy is unbounded below; the solver clamps
/// them, so the identity is still exact and every pose's energy stays
/// non-negative and non-increasing.
#[test]
fn negative_cotangent_weights_do_not_make_the_iteration_diverge() {
    use mfm_processing::refine::{RefineCriterion, refine_region};
    let coarse = normalize_rest(&procedural::capsule(0.5, 0.75, 8, 24).unwrap())
        .unwrap()
        .0;
    let mesh = refine_region(
        &coarse,
        |p| p[0] < 0.0,
        RefineCriterion::MaxEdgeLength(0.02),
    )
    .unwrap();
    let l = mfm_geometry::operators::cotangent_laplacian(&mesh);
    let (cp, ri) = (l.symbolic().col_ptr(), l.symbolic().row_idx());
    let negative = (0..mesh.num_vertices())
        .flat_map(|c| (cp[c]..cp[c + 1]).map(move |k| (c, k)))
        .filter(|&(c, k)| ri[k] != c && l.val()[k] > 0.0)
        .count();
    assert!(negative > 0, "the test mesh needs negative weights");
    let space = space_on(&mesh);
    let arap = Arap::new(&mesh, &space.handles).unwrap();
    let opts = ArapOptions::default();
    let rest = arap.deform(&DeformParams::identity(3), &opts).unwrap();
    assert!(max_diff(&rest.positions, mesh.positions()) < 1e-10);
    assert!(arap.energy(mesh.positions(), &opts).unwrap().abs() < 1e-20);
    for i in 0..3 {
        let out = arap.deform(&space.sample_params(1, i), &opts).unwrap();
        assert!(out.energies.iter().all(|&e| e >= 0.0), "{:?}", out.energies);
        assert!(
            out.energies
                .windows(2)
                .all(|w| w[1] <= w[0] * (1.0 + 1e-12)),
            "{:?}",
            out.energies
        );
        // the pose stays near the rest shape: nothing ran away
        assert!(max_diff(&out.positions, mesh.positions()) < 0.5);
    }
}

#[test]
fn a_rigid_motion_of_all_handles_moves_the_shape_rigidly() {
    let mesh = unit_blob(3);
    let space = space_on(&mesh);
    let arap = Arap::new(&mesh, &space.handles).unwrap();
    // global motion x -> R x + t, written per handle about its own center
    let axis_angle = [0.4, -0.9, 0.3];
    let (r, t) = (axis_angle_to_matrix(axis_angle), [0.2, -0.1, 0.35]);
    let global = |x: [f64; 3]| {
        let y = mat_vec(&r, x);
        [y[0] + t[0], y[1] + t[1], y[2] + t[2]]
    };
    let per_handle = |h: &Handle| {
        let moved = global(h.center);
        RigidParams {
            rotation: axis_angle,
            translation: [
                moved[0] - h.center[0],
                moved[1] - h.center[1],
                moved[2] - h.center[2],
            ],
        }
    };
    let params = DeformParams {
        handles: space.handles.moving.iter().map(per_handle).collect(),
    };
    let opts = ArapOptions {
        max_iterations: 200,
        tolerance: 0.0,
        ..ArapOptions::default()
    };
    let out = arap
        .deform_with_anchor(&per_handle(&space.handles.anchor), &params, &opts)
        .unwrap();
    let expected: Vec<[f64; 3]> = mesh.positions().iter().map(|&p| global(p)).collect();
    let err = max_diff(&out.positions, &expected);
    let e_first = out.energies[0];
    let e_last = *out.energies.last().unwrap();
    eprintln!(
        "rigid motion: {} iterations, energy {e_first:e} -> {e_last:e}, max error {err:e}",
        out.iterations
    );
    assert!(e_last < 1e-20, "energy did not reach zero: {e_last:e}");
    assert!(
        err < 1e-8,
        "not the rigidly moved rest shape: max error {err:e}"
    );
}

#[test]
fn reported_energy_is_the_energy_of_the_result() {
    let mesh = unit_blob(3);
    let space = space_on(&mesh);
    let arap = Arap::new(&mesh, &space.handles).unwrap();
    let params = space.sample_params(3, 1);
    // classic ARAP: the energy of a shape is exact, and equals the last one reported
    let classic = ArapOptions {
        smoothness: 0.0,
        ..ArapOptions::default()
    };
    let out = arap.deform(&params, &classic).unwrap();
    assert_eq!(out.energies.len(), out.iterations + 1);
    let e = arap.energy(&out.positions, &classic).unwrap();
    let last = *out.energies.last().unwrap();
    assert!((e - last).abs() <= 1e-12 * last, "{e} vs {last}");
    // with smoothness, energy() minimizes over the rotations further than
    // the stopped iteration did: a little lower, never higher
    let opts = ArapOptions::default();
    let out = arap.deform(&params, &opts).unwrap();
    let e = arap.energy(&out.positions, &opts).unwrap();
    let last = *out.energies.last().unwrap();
    assert!(
        e <= last * (1.0 + 1e-12) && e > 0.97 * last,
        "{e} vs {last}"
    );
    // handle vertices follow their handle exactly
    for (k, region) in arap.regions().iter().enumerate().skip(1) {
        let h = &space.handles.moving[k - 1];
        let t = params.handles[k - 1].to_transform(h.center);
        for &v in region {
            let want = t.apply(mesh.positions()[v]);
            assert!(max_diff(&[out.positions[v]], &[want]) < 1e-14);
        }
    }
    for &v in &arap.regions()[0] {
        assert_eq!(out.positions[v], mesh.positions()[v]);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]
    /// Every step is an exact minimization or safeguarded, so the energy
    /// never increases (up to round-off), with or without the smoothness
    /// term and the acceleration, and the iterations improve on the
    /// initial guess.
    #[test]
    fn energy_is_non_increasing(
        seed in 0u64..10_000,
        index in 0usize..1000,
        angle in 0.1f64..1.5,
        shift in 0.02f64..0.3,
        smooth in prop::bool::ANY,
        anderson in 0usize..6,
    ) {
        let mesh = unit_blob(2);
        let mut space = space_on(&mesh);
        space.max_angle = angle;
        space.max_shift = shift;
        let arap = Arap::new(&mesh, &space.handles).unwrap();
        let opts = ArapOptions {
            max_iterations: 25,
            tolerance: 0.0,
            anderson,
            smoothness: if smooth { 0.05 } else { 0.0 },
        };
        let out = arap.deform(&space.sample_params(seed, index), &opts).unwrap();
        let e = &out.energies;
        prop_assert!(e[0] > 0.0);
        for w in e.windows(2) {
            prop_assert!(w[1] <= w[0] + 1e-12 * e[0], "energy went up: {:?}", e);
        }
        prop_assert!(e[e.len() - 1] < e[0]);
    }
}

#[test]
fn works_on_a_mesh_with_holes() {
    let mesh = unit_blob(3);
    let punched = punch_holes(&mesh, &[5, 200, 400], 0.06, HoleMetric::Geodesic).unwrap();
    let holed = punched.mesh;
    let topo = Topology::new(holed.num_vertices(), holed.faces());
    assert!(topo.boundary_loops().len() >= 2);
    // the handles of the closed mesh, reused (they must still hold vertices)
    let space = space_on(&mesh);
    let arap = Arap::new(&holed, &space.handles).unwrap();
    let out = arap
        .deform(&space.sample_params(1, 0), &ArapOptions::default())
        .unwrap();
    assert!(out.positions.iter().flatten().all(|x| x.is_finite()));
    assert!(
        out.energies
            .windows(2)
            .all(|w| w[1] <= w[0] * (1.0 + 1e-12))
    );
    assert!(out.iterations >= 1 && out.energies.last().unwrap() < &out.energies[0]);
    // the boundary moved with the surface: the holes stay holes (no vertex
    // of the deformed mesh is far from where its neighbours put it)
    let moved = common::max_diff(&out.positions, holed.positions());
    assert!(moved > 0.02, "nothing moved: {moved}");
}

#[test]
fn wrong_parameter_count_is_an_error() {
    let mesh = unit_blob(2);
    let space = space_on(&mesh);
    let arap = Arap::new(&mesh, &space.handles).unwrap();
    let err = arap
        .deform(&DeformParams::identity(2), &ArapOptions::default())
        .unwrap_err();
    assert!(
        matches!(
            err,
            DeformError::HandleCountMismatch {
                expected: 3,
                found: 2
            }
        ),
        "{err}"
    );
    let mut bad = DeformParams::identity(3);
    bad.handles[1].translation[2] = f64::NAN;
    let err = arap.deform(&bad, &ArapOptions::default()).unwrap_err();
    assert!(
        matches!(err, DeformError::NonFinite { index: 2, .. }),
        "{err}"
    );
    let opts = ArapOptions {
        tolerance: -1.0,
        ..ArapOptions::default()
    };
    let err = arap.deform(&DeformParams::identity(3), &opts).unwrap_err();
    assert!(matches!(
        err,
        DeformError::InvalidParameter {
            name: "tolerance",
            ..
        }
    ));
    let opts = ArapOptions {
        smoothness: f64::NAN,
        ..ArapOptions::default()
    };
    let err = arap.deform(&DeformParams::identity(3), &opts).unwrap_err();
    assert!(matches!(
        err,
        DeformError::InvalidParameter {
            name: "smoothness",
            ..
        }
    ));
    assert!(matches!(
        arap.energy(&mesh.positions()[1..], &ArapOptions::default()),
        Err(DeformError::SizeMismatch { .. })
    ));
}

#[test]
fn empty_and_overlapping_handles_are_errors() {
    let mesh = unit_blob(2);
    let inside = mesh.positions()[0];
    let far = Handle {
        center: [10.0, 0.0, 0.0],
        radius: 0.1,
    };
    let near = Handle {
        center: inside,
        radius: 0.1,
    };
    let set = HandleSet::new(near, vec![far]).unwrap();
    let err = Arap::new(&mesh, &set).unwrap_err();
    assert!(matches!(&err, DeformError::EmptyHandle { handle, .. } if handle == "handle 0"));
    assert!(err.to_string().contains("handle 0"), "{err}");

    let shifted = Handle {
        center: [inside[0] + 0.01, inside[1], inside[2]],
        radius: 0.1,
    };
    let set = HandleSet::new(near, vec![shifted]).unwrap();
    let err = Arap::new(&mesh, &set).unwrap_err();
    assert!(
        matches!(&err, DeformError::OverlappingHandles { first, second, .. } if first == "anchor" && second == "handle 0"),
        "{err}"
    );
    let msg = err.to_string();
    assert!(msg.contains("anchor") && msg.contains("handle 0"), "{msg}");

    let bad = Handle {
        center: inside,
        radius: -1.0,
    };
    assert!(matches!(
        HandleSet::new(bad, vec![]),
        Err(DeformError::InvalidParameter { .. })
    ));
}

#[test]
fn a_component_without_handles_is_an_error() {
    // two disjoint spheres, handles on the first only
    let a = procedural::icosphere(1);
    let (pa, fa) = a.clone().into_parts();
    let n = pa.len() as u32;
    let mut positions = pa.clone();
    positions.extend(pa.iter().map(|p| [p[0] + 5.0, p[1], p[2]]));
    let mut faces = fa.clone();
    faces.extend(fa.iter().map(|f| [f[0] + n, f[1] + n, f[2] + n]));
    let mesh = TriMesh::new(positions, faces).unwrap();
    let set = HandleSet::new(
        Handle {
            center: pa[0],
            radius: 0.3,
        },
        vec![Handle {
            center: pa[3],
            radius: 0.3,
        }],
    )
    .unwrap();
    let err = Arap::new(&mesh, &set).unwrap_err();
    assert!(
        matches!(err, DeformError::UnconstrainedVertex { count, .. } if count == n as usize),
        "{err}"
    );
}
