//! The shared elephant mesh (skipped with a printed reason when
//! `../shared/meshes` is missing): automatic handles at the extremities,
//! usable on the decimated coarse mesh, and a quick generation.
#![allow(clippy::unwrap_used)]

use mfm_deform::{Arap, DeformSpace, HandleSet, normalize_rest, project};
use mfm_geometry::test_support;
use mfm_processing::decimate;
use mfm_processing::holes::edge_path_distances;

#[test]
fn auto_handles_on_the_elephant_sit_at_the_tips() {
    let Some(path) = test_support::shared_mesh("elephant.obj") else {
        return;
    };
    let (rest, scale, shift) = normalize_rest(&mfm_meshio::read_mesh(&path).unwrap()).unwrap();
    let handles = HandleSet::auto(&rest, 5, mfm_deform::DEFAULT_RADIUS_FRACTION).unwrap();
    let regions = handles.regions(&rest).unwrap();
    for (i, r) in regions.iter().enumerate() {
        eprintln!(
            "{}: {:?}, {} vertices",
            handles.name(i),
            handles.get(i).unwrap().center,
            r.len()
        );
        assert!(r.len() >= 20);
    }
    // every moving handle is far from the anchor along the surface: at
    // least half the largest edge-path distance (tips, not the torso)
    let anchor = regions[0][0];
    let d = edge_path_distances(&rest, &[anchor]).unwrap();
    let dmax = d
        .iter()
        .copied()
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max);
    let pos = rest.positions();
    for h in &handles.moving {
        let v = (0..pos.len()).find(|&v| pos[v] == h.center).unwrap();
        assert!(d[v] > 0.5 * dmax, "{:?} at {} of {}", h.center, d[v], dmax);
    }
    // the same handles on the coarse training mesh (original decimated,
    // normalized with the original's transform)
    let coarse = decimate::decimate(&mfm_meshio::read_mesh(&path).unwrap(), 3000, None)
        .unwrap()
        .mesh
        .transformed(scale, shift);
    let space = DeformSpace::new(&rest, handles);
    let arap = Arap::new(&coarse, &space.handles).unwrap();
    let shapes = space.generate_with(&arap, 0, 0..2, |_| {}).unwrap();
    for s in &shapes {
        let p = project(&arap, &space, &s.positions).unwrap();
        assert!(p.mse < 1e-10, "{}", p.mse);
    }
}
