"""Offscreen contact sheets of PLY files with pyvista (`cargo xtask visual-check`).

Usage: python visual_check.py JOB.json RESULT.json

JOB.json (written by xtask/src/visual_check.rs) lists the sheets to draw:

    {"tile": 320, "cmap": "viridis", "field": "first", "range": "auto",
     "up": "y", "azimuth": 30, "elevation": 20, "columns": null,
     "sheets": [{"title": "samples", "out": "/abs/samples.png",
                 "files": [{"path": "/abs/samples/s0.ply", "label": "s0.ply"}]}]}

Each PLY file becomes one tile (or one tile per scalar property with
`"field": "all"`): a mesh with per-vertex scalars is colored by them, a mesh
without is drawn shaded. Tiles are rendered by VTK through one reused offscreen
pyvista plotter, then laid out with matplotlib (title above each tile, color bar
shared by the sheet or one per tile). RESULT.json receives, per sheet, the
number of tiles, what was shown and the files that could not be read.

VTK's PLY reader (which pyvista and ParaView use) keeps only the vertex
properties it knows (x/y/z, nx/ny/nz, u/v, red/green/blue/alpha) and drops
every other one, so the per-vertex scalars that mfm writes (`property double
NAME`) are read here with numpy: `load_ply` returns pyvista's own mesh with
those properties attached as point data.
"""

import json
import math
import sys
import time

import numpy as np

# PLY type names, classic and sized, as numpy codes.
PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}

# Vertex properties that are geometry or VTK-native attributes, not signals.
NOT_SIGNALS = {"x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha", "u", "v",
               "texture_u", "texture_v", "s", "t"}

SHADE_COLOR = "#c9d3e0"
BACKGROUND = "white"
DPI = 100
# fraction of the tile the mesh spans along its longer projected extent
FILL = 0.92


class PlyError(ValueError):
    """A PLY file this reader cannot make sense of (the message names the file)."""


def _parse_header(path, data):
    """(format, [(element, count, [(property, numpy code or None for lists)])], body offset)."""
    if not data.startswith(b"ply"):
        raise PlyError(f"{path}: not a PLY file (it does not start with `ply`)")
    end = data.find(b"end_header")
    if end < 0:
        raise PlyError(f"{path}: the header has no `end_header` line")
    newline = data.find(b"\n", end)
    if newline < 0:
        raise PlyError(f"{path}: nothing after `end_header`")
    fmt = None
    elements = []
    for number, line in enumerate(data[:end].decode("ascii", "replace").splitlines()[1:], 2):
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format" and len(tok) >= 2:
            fmt = tok[1]
        elif tok[0] == "element" and len(tok) == 3:
            try:
                elements.append((tok[1], int(tok[2]), []))
            except ValueError:
                raise PlyError(f"{path}: header line {number}: bad element count `{tok[2]}`")
        elif tok[0] == "property" and elements:
            if len(tok) == 5 and tok[1] == "list":
                elements[-1][2].append((tok[4], None))
            elif len(tok) == 3 and tok[1] in PLY_TYPES:
                elements[-1][2].append((tok[2], PLY_TYPES[tok[1]]))
            else:
                raise PlyError(f"{path}: header line {number}: cannot read `{line.strip()}`")
        else:
            raise PlyError(f"{path}: header line {number}: unexpected `{line.strip()}`")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise PlyError(f"{path}: unknown PLY format `{fmt}`")
    return fmt, elements, newline + 1


def read_vertex_properties(path):
    """All scalar properties of the `vertex` element, in file order, as float64 arrays.

    Returns a dict {name: array of length V}. Elements before `vertex` are
    skipped (they must not have list properties in a binary file, since their
    size would then be unknown without parsing them). Cost: O(V) numpy work.
    """
    with open(path, "rb") as fh:
        data = fh.read()
    fmt, elements, offset = _parse_header(path, data)
    names = [e[0] for e in elements]
    if "vertex" not in names:
        raise PlyError(f"{path}: no `vertex` element")
    k = names.index("vertex")
    _, count, props = elements[k]
    if any(code is None for _, code in props):
        raise PlyError(f"{path}: the `vertex` element has a list property; only scalars are supported")
    if fmt == "ascii":
        tokens = data[offset:].split()
        start = sum(c * len(p) for _, c, p in elements[:k])
        if any(code is None for _, _, p in elements[:k] for _, code in p):
            raise PlyError(f"{path}: elements with list properties before `vertex` are not supported")
        need = count * len(props)
        chunk = tokens[start:start + need]
        if len(chunk) < need:
            raise PlyError(f"{path}: the file ends inside the vertex data ({len(chunk)} of {need} numbers)")
        try:
            table = np.array(chunk, dtype=np.float64).reshape(count, len(props))
        except ValueError as e:
            raise PlyError(f"{path}: bad number in the vertex data ({e})")
        return {name: table[:, j].copy() for j, (name, _) in enumerate(props)}
    endian = "<" if fmt == "binary_little_endian" else ">"
    for name, c, p in elements[:k]:
        if any(code is None for _, code in p):
            raise PlyError(f"{path}: element `{name}` with a list property comes before `vertex`")
        offset += c * sum(np.dtype(code).itemsize for _, code in p)
    try:
        dtype = np.dtype([(name, endian + code) for name, code in props])
    except ValueError as e:
        raise PlyError(f"{path}: bad vertex properties ({e})")
    if offset + count * dtype.itemsize > len(data):
        raise PlyError(f"{path}: the file ends inside the vertex data")
    table = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
    return {name: table[name].astype(np.float64) for name, _ in props}


def load_ply(path):
    """pyvista's reading of the PLY file, with every vertex scalar property attached.

    Geometry and faces come from `pyvista.read` (VTK's reader); the vertex
    properties it drops are read by `read_vertex_properties` and added as
    float64 point data under their PLY names (x/y/z also replace VTK's float32
    points, so coordinates are exact). Raises PlyError when the two readers
    disagree on the vertex count.
    """
    import pyvista as pv

    props = read_vertex_properties(path)
    mesh = pv.read(path)
    n = len(next(iter(props.values()))) if props else 0
    if mesh.n_points != n:
        raise PlyError(f"{path}: VTK read {mesh.n_points} vertices, the header declares {n}")
    if all(c in props for c in "xyz"):
        mesh.points = np.column_stack([props["x"], props["y"], props["z"]])
    for name, values in props.items():
        if name not in NOT_SIGNALS:
            mesh.point_data[name] = values
    return mesh


def signal_names(mesh):
    """The point arrays of `load_ply`'s mesh that are signals (file order)."""
    return [n for n in mesh.point_data.keys() if n not in NOT_SIGNALS and n not in ("RGB", "Normals", "TCoords")
            and mesh.point_data[n].ndim == 1]


def _finite_range(values):
    v = values[np.isfinite(values)]
    if v.size == 0:
        return (0.0, 1.0)
    lo, hi = float(v.min()), float(v.max())
    if lo == hi:
        pad = 0.5 if lo == 0 else abs(lo) * 0.01
        lo, hi = lo - pad, hi + pad
    return (lo, hi)


def _shorten(text, limit):
    return text if len(text) <= limit else text[: limit // 2 - 1] + "…" + text[-(limit - limit // 2):]


def plan_tiles(files, field):
    """Reads the files of one sheet and decides what each tile shows.

    Returns a list of dicts: label, mesh (or None), field (or None), error.
    """
    tiles = []
    for f in files:
        try:
            mesh = load_ply(f["path"])
        except Exception as e:  # one unreadable file must not stop the sheet
            tiles.append({"label": f["label"], "mesh": None, "field": None, "rgb": False, "error": str(e)})
            continue
        names = signal_names(mesh)
        if field == "all" and names:
            chosen = names
        elif field not in ("first", "all"):
            if field not in names:
                tiles.append({"label": f["label"], "mesh": None, "field": None, "rgb": False,
                              "error": f"no vertex property `{field}` (has: {', '.join(names) or 'none'})"})
                continue
            chosen = [field]
        else:
            chosen = names[:1] or [None]
        for name in chosen:
            rgb = name is None and "RGB" in mesh.point_data.keys()
            tiles.append({"label": f["label"], "mesh": mesh, "field": name, "rgb": rgb, "error": None})
    return tiles


def camera_direction(up, azimuth, elevation):
    """Unit vector from the focal point to the camera, and the up vector.

    Same rig as `mfm render`: with y up, azimuth 0 and elevation 0 look from
    +z, positive azimuth turns towards +x, positive elevation towards +y; with
    z up the rig is rotated so that it looks from -y and +z is up.
    """
    az, el = math.radians(azimuth), math.radians(elevation)
    x, y, z = math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)
    if up == "z":
        return (x, -z, y), (0.0, 0.0, 1.0)
    return (x, y, z), (0.0, 1.0, 0.0)


def fit_camera(plotter, points, direction, up):
    """Orthographic camera looking along -direction, framing the projected points.

    The projections of the vertices on the image axes (not the bounding
    sphere) span FILL of the tile along the tighter direction, centred, so
    elongated meshes are neither cropped nor tiny.
    """
    d = np.asarray(direction, dtype=float)
    d /= np.linalg.norm(d)
    right = np.cross(np.asarray(up, dtype=float), d)
    right /= np.linalg.norm(right)
    image_up = np.cross(d, right)
    centre = points.mean(axis=0) if len(points) else np.zeros(3)
    rel = points - centre
    r, u, depth = rel @ right, rel @ image_up, rel @ d
    lo_r, hi_r = (r.min(), r.max()) if len(r) else (-1.0, 1.0)
    lo_u, hi_u = (u.min(), u.max()) if len(u) else (-1.0, 1.0)
    focal = centre + right * 0.5 * (lo_r + hi_r) + image_up * 0.5 * (lo_u + hi_u)
    half = max(0.5 * (hi_r - lo_r), 0.5 * (hi_u - lo_u), 1e-12)
    reach = max(float(np.abs(depth).max()) if len(depth) else 1.0, half)
    plotter.camera_position = [tuple(focal + d * 4.0 * reach), tuple(focal), tuple(image_up)]
    plotter.camera.parallel_projection = True
    plotter.camera.parallel_scale = half / FILL
    plotter.renderer.ResetCameraClippingRange()


def render_tiles(plotter, tiles, cmap, ranges, camera):
    """Renders each readable tile into an RGB array with the shared plotter."""
    direction, up = camera
    images = []
    for t in tiles:
        if t["mesh"] is None:
            images.append(None)
            continue
        plotter.clear_actors()
        if t["rgb"]:
            plotter.add_mesh(t["mesh"], scalars="RGB", rgb=True, smooth_shading=True,
                             show_scalar_bar=False)
        elif t["field"] is None:
            plotter.add_mesh(t["mesh"], color=SHADE_COLOR, smooth_shading=True, specular=0.3,
                             specular_power=20.0, show_scalar_bar=False)
        else:
            plotter.add_mesh(t["mesh"], scalars=t["field"], cmap=cmap, clim=ranges[id(t)],
                             smooth_shading=True, nan_color="magenta", show_scalar_bar=False,
                             ambient=0.35, diffuse=0.7, specular=0.0)
        fit_camera(plotter, np.asarray(t["mesh"].points, dtype=float), direction, up)
        # screenshot() reads the last frame after the first one: render this one
        plotter.render()
        images.append(plotter.screenshot(return_img=True))
    return images


def compose(sheet, tiles, images, ranges, shared, cmap, tile, columns):
    """Lays the tiles out with matplotlib and writes the PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import cm, colors

    n = len(tiles)
    cols = columns or max(1, math.ceil(math.sqrt(n)))
    cols = min(cols, n)
    rows = math.ceil(n / cols)
    any_scalar = any(t["field"] for t in tiles)
    head, title_h = 36, 34
    bar_h = 44 if (any_scalar and not shared) else 0
    foot = 64 if (any_scalar and shared) else 8
    cell_h = title_h + tile + bar_h
    width, height = cols * tile, head + rows * cell_h + foot
    fig = plt.figure(figsize=(width / DPI, height / DPI), dpi=DPI, facecolor=BACKGROUND)
    fig.text(0.5, 1 - (head / 2) / height, sheet["title"], ha="center", va="center", fontsize=12,
             weight="bold")
    limit = max(12, tile // 7)
    for i, (t, img) in enumerate(zip(tiles, images)):
        r, c = divmod(i, cols)
        x0 = c * tile / width
        top = head + r * cell_h
        if t["error"]:
            sub, sub_color = "cannot read: see below", "red"
        elif t["field"]:
            lo, hi = _finite_range(t["mesh"].point_data[t["field"]])
            sub, sub_color = f"{t['field']}  [{lo:.3g}, {hi:.3g}]", "black"
        elif t["rgb"]:
            sub, sub_color = f"vertex colors, {t['mesh'].n_points} vertices", "black"
        else:
            sub, sub_color = f"shaded, {t['mesh'].n_points} vertices", "black"
        fig.text(x0 + 0.5 * tile / width, 1 - (top + 11) / height, _shorten(t["label"], limit),
                 ha="center", va="center", fontsize=9, weight="bold")
        fig.text(x0 + 0.5 * tile / width, 1 - (top + 26) / height, _shorten(sub, limit + 4),
                 ha="center", va="center", fontsize=8, color=sub_color)
        ax = fig.add_axes([x0, 1 - (top + title_h + tile) / height, tile / width, tile / height])
        ax.set_axis_off()
        if img is None:
            ax.imshow(np.full((tile, tile, 3), 235, dtype=np.uint8))
            ax.text(0.5, 0.5, _wrap(t["error"], max(16, tile // 7)), ha="center", va="center",
                    fontsize=7, color="red", transform=ax.transAxes)
        else:
            ax.imshow(img)
        if bar_h and t["field"]:
            cax = fig.add_axes([x0 + 0.12 * tile / width, 1 - (top + title_h + tile + 16) / height,
                                0.76 * tile / width, 10 / height])
            norm = colors.Normalize(*ranges[id(t)])
            cb = fig.colorbar(cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax, orientation="horizontal")
            cb.ax.tick_params(labelsize=7, length=2, pad=1)
            cb.ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(4))
    if foot > 8:
        lo, hi = shared
        fields = sorted({t["field"] for t in tiles if t["field"]})
        cax = fig.add_axes([0.2, (foot - 22) / height, 0.6, 12 / height])
        cb = fig.colorbar(cm.ScalarMappable(norm=colors.Normalize(lo, hi), cmap=cmap), cax=cax,
                          orientation="horizontal")
        cb.ax.tick_params(labelsize=8)
        cb.set_label(", ".join(fields) + " (one color range for the sheet)", fontsize=8, labelpad=2)
    fig.savefig(sheet["out"], dpi=DPI, facecolor=BACKGROUND)
    plt.close(fig)


def _wrap(text, width):
    words, lines, line = text.split(), [], ""
    for w in words:
        while len(w) > width:
            if line:
                lines.append(line)
                line = ""
            lines.append(w[:width])
            w = w[width:]
        if len(line) + len(w) + 1 > width and line:
            lines.append(line)
            line = w
        else:
            line = f"{line} {w}".strip()
    if line:
        lines.append(line)
    return "\n".join(lines[:12])


def main(job_path, result_path):
    with open(job_path) as fh:
        job = json.load(fh)
    import pyvista as pv

    tile = int(job["tile"])
    plotter = pv.Plotter(off_screen=True, window_size=[tile, tile])
    plotter.set_background(BACKGROUND)
    window = getattr(plotter, "render_window", None) or plotter.ren_win
    results = []
    for sheet in job["sheets"]:
        start = time.perf_counter()
        tiles = plan_tiles(sheet["files"], job["field"])
        scalar_tiles = [t for t in tiles if t["field"]]
        fields = {t["field"] for t in scalar_tiles}
        mode = job["range"]
        share = bool(scalar_tiles) and (mode == "shared" or (mode == "auto" and len(fields) == 1))
        shared = None
        if share:
            values = np.concatenate([t["mesh"].point_data[t["field"]] for t in scalar_tiles])
            shared = _finite_range(values)
        ranges = {id(t): shared or _finite_range(t["mesh"].point_data[t["field"]]) for t in scalar_tiles}
        camera = camera_direction(job["up"], float(job["azimuth"]), float(job["elevation"]))
        images = render_tiles(plotter, tiles, job["cmap"], ranges, camera)
        compose(sheet, tiles, images, ranges, shared, job["cmap"], tile, job.get("columns"))
        results.append({
            "out": sheet["out"],
            "title": sheet["title"],
            "tiles": len(tiles),
            "colored": len(scalar_tiles),
            "shaded": sum(1 for t in tiles if t["mesh"] is not None and not t["field"] and not t["rgb"]),
            "rgb": sum(1 for t in tiles if t["rgb"]),
            "fields": sorted(fields),
            "range": list(shared) if shared else None,
            "errors": [{"file": t["label"], "error": t["error"]} for t in tiles if t["error"]],
            "seconds": time.perf_counter() - start,
        })
    plotter.close()
    with open(result_path, "w") as fh:
        json.dump({"backend": window.GetClassName(), "sheets": results}, fh, indent=1)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: visual_check.py JOB.json RESULT.json")
    main(sys.argv[1], sys.argv[2])
