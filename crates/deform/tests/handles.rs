//! Handle placement and handle regions across triangulations.
#![allow(clippy::unwrap_used)]

mod common;

use common::unit_blob;
use mfm_deform::{DeformError, Handle, HandleSet};
use mfm_geometry::mesh::{norm, sub};
use mfm_geometry::{operators, subdivide};
use mfm_processing::holes::edge_path_distances;

#[test]
fn auto_places_the_anchor_at_the_centroid_and_handles_far_along_the_surface() {
    let mesh = unit_blob(3);
    let set = HandleSet::auto(&mesh, 3, 0.1).unwrap();
    let pos = mesh.positions();
    let radius = 0.1 * mesh.bounding_box_diagonal();
    // anchor: the vertex nearest the mass-weighted centroid
    let m = operators::lumped_mass(&mesh);
    let total: f64 = m.iter().sum();
    let c: [f64; 3] =
        std::array::from_fn(|k| pos.iter().zip(&m).map(|(p, w)| w * p[k]).sum::<f64>() / total);
    let best = (0..pos.len())
        .min_by(|&a, &b| norm(sub(pos[a], c)).total_cmp(&norm(sub(pos[b], c))))
        .unwrap();
    assert_eq!(set.anchor.center, pos[best]);
    assert!(set.iter().all(|h| h.radius == radius));
    // the first moving handle is the vertex farthest from the anchor along
    // the mesh (its ball is far from the anchor's on this blob)
    let d = edge_path_distances(&mesh, &[best]).unwrap();
    let far = (0..pos.len())
        .max_by(|&a, &b| d[a].total_cmp(&d[b]).then(b.cmp(&a)))
        .unwrap();
    assert_eq!(set.moving[0].center, pos[far]);
    // balls are disjoint: regions on any triangulation cannot overlap
    let centers: Vec<[f64; 3]> = set.iter().map(|h| h.center).collect();
    for i in 0..centers.len() {
        for j in 0..i {
            assert!(norm(sub(centers[i], centers[j])) > 2.0 * radius);
        }
    }
}

#[test]
fn regions_are_consistent_across_refinement() {
    let mesh = unit_blob(3);
    let set = HandleSet::auto(&mesh, 3, 0.08).unwrap();
    let fine = subdivide::midpoint(&mesh).unwrap();
    let coarse_regions = set.regions(&mesh).unwrap();
    let fine_regions = set.regions(&fine).unwrap();
    for (c, f) in coarse_regions.iter().zip(&fine_regions) {
        // the first V vertices of the refinement are the coarse vertices
        let f_old: Vec<usize> = f
            .iter()
            .copied()
            .filter(|&v| v < mesh.num_vertices())
            .collect();
        assert_eq!(c, &f_old);
        assert!(f.len() > 2 * c.len(), "{} vs {}", f.len(), c.len());
    }
}

#[test]
fn auto_fails_clearly_when_handles_do_not_fit() {
    let mesh = unit_blob(2);
    let err = HandleSet::auto(&mesh, 30, 0.2).unwrap_err();
    assert!(matches!(err, DeformError::HandlePlacement { .. }), "{err}");
    assert!(err.to_string().contains("smaller"), "{err}");
    let err = HandleSet::auto(&mesh, 3, 0.0).unwrap_err();
    assert!(matches!(
        err,
        DeformError::InvalidParameter {
            name: "radius_fraction",
            ..
        }
    ));
}

#[test]
fn empty_region_names_the_handle_and_the_distance() {
    let mesh = unit_blob(2);
    let set = HandleSet::new(
        Handle {
            center: mesh.positions()[0],
            radius: 0.1,
        },
        vec![
            Handle {
                center: mesh.positions()[100],
                radius: 0.1,
            },
            Handle {
                center: [0.0, 0.0, 0.0],
                radius: 0.01,
            },
        ],
    )
    .unwrap();
    let err = set.regions(&mesh).unwrap_err();
    match &err {
        DeformError::EmptyHandle {
            handle, nearest, ..
        } => {
            assert_eq!(handle, "handle 1");
            assert!(*nearest > 0.01);
        }
        other => panic!("unexpected {other}"),
    }
}

#[test]
fn handle_sets_round_trip_through_json() {
    let mesh = unit_blob(2);
    let set = HandleSet::auto(&mesh, 3, 0.1).unwrap();
    let text = serde_json::to_string(&set).unwrap();
    let back: HandleSet = serde_json::from_str(&text).unwrap();
    assert_eq!(back, set);
    assert_eq!(set.len(), 4);
    assert_eq!(set.name(0), "anchor");
    assert_eq!(set.name(3), "handle 2");
    assert_eq!(set.get(3), Some(&set.moving[2]));
    assert_eq!(set.get(4), None);
}
