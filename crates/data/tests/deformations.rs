//! Deformation datasets: files and manifest round trip, damaged meshes keep
//! the handle regions.
#![allow(clippy::unwrap_used)]

use mfm_data::dataset::Dataset;
use mfm_data::deformations::{
    self, Damage, DeformManifest, DeformMeshes, PARAMS_FILE, damaged_mesh,
};
use mfm_geometry::procedural;

fn meshes() -> DeformMeshes {
    let capsule = procedural::capsule(0.5, 0.75, 16, 48).unwrap();
    DeformMeshes::from_mesh(&capsule, 600).unwrap()
}

#[test]
fn meshes_are_normalized_coarse_and_finer() {
    let m = meshes();
    assert!((m.original.bounding_box_diagonal() - 1.0).abs() < 1e-9);
    assert!(m.coarse.num_faces() <= 600 && m.coarse.num_faces() >= 590);
    assert!(m.eval.num_vertices() > 2 * m.coarse.num_vertices());
    // refinement keeps the coarse surface: same area
    assert!((m.eval.total_area() - m.coarse.total_area()).abs() < 1e-9);
    let err = DeformMeshes::from_mesh(&m.original, 10).unwrap_err();
    assert!(err.to_string().contains("100 faces"), "{err}");
}

#[test]
fn written_datasets_record_the_space() {
    let m = meshes();
    let space = deformations::space_for(&m.original, 2, 0.15, 0.4, 0.08).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let data = deformations::write_dataset(
        &dir.path().join("d"),
        &m.coarse,
        &space,
        7,
        3..7,
        m.normalization,
        m.frame,
        "coarse",
        "test",
        false,
    )
    .unwrap();
    let opened = Dataset::open(data.dir()).unwrap();
    assert_eq!(opened.manifest().frame, Some(m.frame));
    let manifest = DeformManifest::of(&opened).unwrap().unwrap();
    assert_eq!(manifest.space, space);
    assert_eq!((manifest.first, manifest.mesh_role.as_str()), (3, "coarse"));
    let params: Vec<mfm_deform::DeformParams> =
        serde_json::from_str(&std::fs::read_to_string(data.dir().join(PARAMS_FILE)).unwrap())
            .unwrap();
    assert_eq!(params.len(), 4);
    assert_eq!(params[0], space.sample_params(7, 3));
}

#[test]
fn damaged_meshes_keep_every_handle_region() {
    let m = meshes();
    let space = deformations::space_for(&m.original, 2, 0.15, 0.4, 0.08).unwrap();
    for damage in Damage::ALL {
        let d = damaged_mesh(&m.eval, &space, damage, 3).unwrap();
        let regions = space.handles.regions(&d).unwrap();
        assert!(regions.iter().all(|r| !r.is_empty()), "{damage:?}");
        match damage {
            Damage::MildFlips | Damage::SevereFlips => {
                assert_eq!(d.num_vertices(), m.eval.num_vertices());
                assert_ne!(d.faces(), m.eval.faces(), "{damage:?}");
            }
            _ => assert!(d.num_faces() < m.eval.num_faces(), "{damage:?}"),
        }
        assert_eq!(damage.name().parse::<Damage>().unwrap(), damage);
    }
    assert!("dents".parse::<Damage>().is_err());
    // a space of another surface (or of this one in other units) is refused
    let scaled = mfm_geometry::TriMesh::new(
        m.eval
            .positions()
            .iter()
            .map(|p| p.map(|x| 2.0 * x))
            .collect(),
        m.eval.faces().to_vec(),
    )
    .unwrap();
    let e = damaged_mesh(&scaled, &space, Damage::SmallHoles, 3)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bounding-box diagonal") && e.contains("not the space's surface"),
        "{e}"
    );
    let elsewhere = mfm_geometry::TriMesh::new(
        m.eval
            .positions()
            .iter()
            .map(|p| [p[0] + 0.5, p[1], p[2]])
            .collect(),
        m.eval.faces().to_vec(),
    )
    .unwrap();
    let e = deformations::space_fits(&elsewhere, &space)
        .unwrap_err()
        .to_string();
    assert!(e.contains("does not fit this mesh"), "{e}");
    deformations::space_fits(&m.eval, &space).unwrap();
    deformations::space_fits(&m.coarse, &space).unwrap();
    // larger holes remove more
    let faces = |d| damaged_mesh(&m.eval, &space, d, 3).unwrap().num_faces();
    assert!(faces(Damage::LargeHoles) < faces(Damage::SmallHoles));
}
