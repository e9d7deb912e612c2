//! Property tests: the renderer never panics on degenerate geometry or odd
//! views, and always returns an image of the requested size.

use mfm_geometry::TriMesh;
use mfm_render::{
    ColorRange, Colormap, GridOptions, Panel, Projection, RenderOptions, Shading, UpAxis, View,
    Wireframe, render_grid, render_mesh,
};
use proptest::prelude::*;

/// Coordinates on a coarse grid so that coincident points, collinear and
/// zero-area triangles are common; occasionally huge or tiny.
fn coordinate() -> impl Strategy<Value = f64> {
    prop_oneof![
        8 => (-2i32..=2).prop_map(f64::from),
        1 => Just(1e-300),
        1 => Just(1e12),
    ]
}

fn soup() -> impl Strategy<Value = (Vec<[f64; 3]>, Vec<[u32; 3]>)> {
    (3usize..8).prop_flat_map(|n| {
        let points = prop::collection::vec([coordinate(), coordinate(), coordinate()], n);
        let faces = prop::collection::vec(
            (0..n as u32, 1..n as u32, 1..n as u32).prop_filter_map(
                "distinct",
                move |(a, b, c)| {
                    let (b, c) = ((a + b) % n as u32, (a + c) % n as u32);
                    (b != c).then_some([a, b, c])
                },
            ),
            1..12,
        );
        (points, faces)
    })
}

fn scalar() -> impl Strategy<Value = f64> {
    prop_oneof![
        6 => -3.0..3.0f64,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(0.0),
    ]
}

fn view() -> impl Strategy<Value = View> {
    (
        -720.0..720.0f64,
        -120.0..120.0f64,
        any::<bool>(),
        prop_oneof![
            Just(Projection::Orthographic),
            (0.0..200.0f64).prop_map(|fov_deg| Projection::Perspective { fov_deg }),
        ],
        0.0..1.5f64,
    )
        .prop_map(
            |(azimuth_deg, elevation_deg, z_up, projection, fill)| View {
                azimuth_deg,
                elevation_deg,
                up: if z_up { UpAxis::Z } else { UpAxis::Y },
                projection,
                fill,
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn degenerate_soups_render_without_panicking(
        (points, faces) in soup(),
        view in view(),
        values in prop::collection::vec(scalar(), 8),
        width in 1u32..40,
        height in 1u32..40,
        supersample in 1u32..4,
        flags in any::<(bool, bool, bool, bool)>(),
    ) {
        let mesh = TriMesh::new(points, faces).expect("valid indices by construction");
        let scalars = &values[..mesh.num_vertices()];
        let (colorbar, wire, symmetric, flat) = flags;
        let opts = RenderOptions {
            width,
            height,
            view,
            supersample,
            colorbar,
            wireframe: wire.then(Wireframe::default),
            range: if symmetric { ColorRange::Symmetric } else { ColorRange::Auto },
            colormap: if symmetric { Colormap::CoolWarm } else { Colormap::Viridis },
            shading: if flat { Shading::Flat } else { Shading::Smooth },
            ..RenderOptions::default()
        };
        let img = render_mesh(&mesh, Some(scalars), &opts).expect("valid options");
        prop_assert_eq!(img.dimensions(), (width, height));
        let plain = render_mesh(&mesh, None, &opts).expect("valid options");
        prop_assert_eq!(plain.dimensions(), (width, height));
    }

    #[test]
    fn coincident_vertices_render_a_dot_at_most(
        p in [coordinate(), coordinate(), coordinate()],
        view in view(),
    ) {
        let mesh = TriMesh::new(vec![p; 4], vec![[0, 1, 2], [1, 2, 3]]).expect("valid");
        let opts = RenderOptions { view, ..RenderOptions::with_size(24, 24) };
        let img = render_mesh(&mesh, None, &opts).expect("valid options");
        // zero-area triangles cover no sample
        prop_assert!(img.pixels().all(|px| px.0 == [255, 255, 255]));
    }

    #[test]
    fn grids_of_soups_have_the_layout_size(
        (points, faces) in soup(),
        columns in 1usize..4,
        count in 1usize..5,
        title in prop::option::of("[a-zA-Zλ ]{0,12}"),
    ) {
        let mesh = TriMesh::new(points, faces).expect("valid");
        let values: Vec<f64> = (0..mesh.num_vertices()).map(|i| i as f64).collect();
        let panels: Vec<Panel<'_>> = (0..count)
            .map(|i| Panel::new(&mesh, (i % 2 == 0).then_some(&values[..]), format!("#{i}")))
            .collect();
        let opts = GridOptions {
            panel: RenderOptions { colorbar: true, ..RenderOptions::with_size(20, 16) },
            title,
            ..GridOptions::default()
        };
        let layout = mfm_render::grid_layout(&panels, columns, &opts).expect("layout");
        let img = render_grid(&panels, columns, &opts).expect("renders");
        prop_assert_eq!(img.dimensions(), (layout.width, layout.height));
        prop_assert_eq!(layout.rows as usize, count.div_ceil(columns));
    }
}
