"""Regenerate the colormap anchor tables of mfm's software renderer.

Usage: colormap_tables.py [OUT]

Samples matplotlib's colormaps at ANCHORS evenly spaced points t = i / (ANCHORS - 1)
and writes them as a Rust source file (default: the renderer's
crates/geometry/src/render/colormap_tables.rs, relative to the repository root).
The renderer interpolates linearly between anchors; with 65 anchors the result
stays within 3 of 255 levels of matplotlib's own 256-entry lookup tables.

Only the numbers come from matplotlib (they are the definition of the maps);
the file is plain data and needs no Python at run time.
"""

import os
import sys

import matplotlib
import numpy as np

ANCHORS = 65
MAPS = [
    ("VIRIDIS", "viridis", "matplotlib `viridis` (perceptually uniform, sequential)"),
    ("COOLWARM", "coolwarm", "matplotlib `coolwarm` (Moreland's diverging blue-white-red)"),
]


def main(argv):
    root = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
    default = os.path.join(root, "crates", "geometry", "src", "render", "colormap_tables.rs")
    out = argv[1] if len(argv) > 1 else default
    t = np.linspace(0.0, 1.0, ANCHORS)
    lines = [
        "//! Colormap anchor tables (generated: do not edit by hand).",
        "//!",
        "//! Written by `xtask/python/colormap_tables.py` from matplotlib "
        + matplotlib.__version__
        + ":",
        f"//! each table holds the map's RGB (in `[0, 1]`) at {ANCHORS} evenly spaced",
        "//! points `t = i / (N - 1)`.",
        "",
        "/// Number of anchors per table.",
        f"pub(crate) const ANCHORS: usize = {ANCHORS};",
    ]
    for const, name, doc in MAPS:
        rgb = matplotlib.colormaps[name](t)[:, :3]
        lines.append("")
        lines.append(f"/// {doc}.")
        lines.append(f"pub(crate) const {const}: [[f32; 3]; ANCHORS] = [")
        for r, g, b in rgb:
            lines.append(f"    [{r:.6f}, {g:.6f}, {b:.6f}],")
        lines.append("];")
    with open(out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv)
