"""The Foxglove layout's panels rendered from a bag with matplotlib (for docs and for machines without a
viewer).

Reads the Foxglove channels of an MCAP file (as written by :mod:`flexsheet.viz.foxglove_bag` or the viz
bridge), decodes them against the schemas stored in the file (protobuf FileDescriptorSets with the
``protobuf`` package, JSON), and draws what ``docs/foxglove_layout.json`` shows: the 3-D scene at one
instant (``/viz/scene``), the camera images and the rendered pair nearest to it, and the Δθ, latency and
tension plots of ``/viz/metrics`` over the whole bag. Writes a PNG (Agg) and a JSON of the plotted numbers.
This is not Foxglove: it draws the same decoded messages with matplotlib's simpler 3-D renderer.

    python -m flexsheet.viz.preview run_foxglove.mcap docs/figures/viz/layout_preview.png
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from flexsheet.viz.foxglove import CAMERA_LEFT, CAMERA_RIGHT, METRICS, RENDER_IMAGE, SCENE
from flexsheet.viz.layout import PLOTS

__all__ = ["read_foxglove", "render", "main"]

_IMAGES = (CAMERA_LEFT, CAMERA_RIGHT, RENDER_IMAGE)


def read_foxglove(path: str | Path) -> dict[str, list[tuple[float, object]]]:
    """topic → [(log time s, decoded message)] for the protobuf and JSON channels of an MCAP file (the
    flexsheet-msgpack channels are skipped). Scenes and images are kept as protobuf messages, JSON as dicts.
    Raises ``ValueError`` if the file is not MCAP."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
    from mcap.reader import make_reader

    classes: dict[int, object] = {}
    out: dict[str, list] = defaultdict(list)
    with open(path, "rb") as fh:
        try:
            reader = make_reader(fh)
            it = reader.iter_messages()
            for schema, channel, message in it:
                t = message.log_time / 1e9
                if channel.message_encoding == "json":
                    out[channel.topic].append((t, json.loads(message.data)))
                elif channel.message_encoding == "protobuf":
                    cls = classes.get(schema.id)
                    if cls is None:
                        pool = descriptor_pool.DescriptorPool()
                        for f in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
                            pool.Add(f)
                        cls = classes[schema.id] = message_factory.GetMessageClass(
                            pool.FindMessageTypeByName(schema.name))
                    out[channel.topic].append((t, cls.FromString(message.data)))
        except Exception as exc:  # the mcap reader raises several types on a non-MCAP file
            if not out:
                raise ValueError(f"{path}: cannot read as MCAP ({type(exc).__name__}: {exc})") from None
            raise
    return out


def _get(d: dict, path: str):
    for k in path.split("."):
        d = d.get(k) if isinstance(d, dict) else None
    return d


def _rgba(c) -> tuple:
    return (c.r, c.g, c.b, c.a)


def _quat_rot(q) -> np.ndarray:
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _draw_scene(ax, scene) -> dict:
    """Draw a decoded foxglove.SceneUpdate on a 3-D axes; returns counts of what was drawn."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    drawn: dict[str, int] = defaultdict(int)
    for e in scene.entities:
        for tri in e.triangles:
            P = np.array([[p.x, p.y, p.z] for p in tri.points])
            idx = np.asarray(tri.indices, dtype=int).reshape(-1, 3) if len(tri.indices) else \
                np.arange(len(P)).reshape(-1, 3)
            pc = Poly3DCollection(P[idx], facecolor=_rgba(tri.color), edgecolor="none", linewidth=0)
            ax.add_collection3d(pc)
            drawn[f"{e.id}:triangles"] += len(idx)
        for ln in e.lines:
            P = np.array([[p.x, p.y, p.z] for p in ln.points])
            segs = P.reshape(-1, 2, 3) if ln.type == 2 else np.stack([P[:-1], P[1:]], 1)  # 2: LINE_LIST
            ax.add_collection3d(Line3DCollection(segs, colors=[_rgba(ln.color)], linewidths=0.8))
            drawn[f"{e.id}:lines"] += len(segs)
        for cy in e.cylinders:
            p = np.array([cy.pose.position.x, cy.pose.position.y, cy.pose.position.z])
            axis = _quat_rot(cy.pose.orientation)[:, 2] * cy.size.z / 2
            if e.id == "object":  # the undeformed cylinder: its outline
                ax.plot(*np.stack([p - axis, p + axis]).T, color=_rgba(cy.color), lw=8, solid_capstyle="butt")
            else:
                ax.plot(*np.stack([p - axis, p + axis]).T, color=_rgba(cy.color), lw=max(1.0, cy.size.x * 60),
                        solid_capstyle="round")
            drawn[f"{e.id}:cylinders"] += 1
        for cu in e.cubes:
            p = np.array([cu.pose.position.x, cu.pose.position.y, cu.pose.position.z])
            half = _quat_rot(cu.pose.orientation)[:, 2] * cu.size.z / 2
            ax.plot(*np.stack([p - half, p + half]).T, color=_rgba(cu.color), lw=4)
            drawn[f"{e.id}:cubes"] += 1
        for sp in e.spheres:
            ax.scatter([sp.pose.position.x], [sp.pose.position.y], [sp.pose.position.z],
                       color=[_rgba(sp.color)],
                       s=max(6.0, sp.size.x * 2500), depthshade=False)
            drawn[f"{e.id}:spheres"] += 1
        for ar in e.arrows:
            p = np.array([ar.pose.position.x, ar.pose.position.y, ar.pose.position.z])
            d = _quat_rot(ar.pose.orientation)[:, 0] * (ar.shaft_length + ar.head_length)
            ax.quiver(*p, *d, color=_rgba(ar.color), linewidth=1.5, arrow_length_ratio=0.3)
            drawn[f"{e.id}:arrows"] += 1
        for tx in e.texts:
            ax.text(tx.pose.position.x, tx.pose.position.y, tx.pose.position.z, tx.text, color="w",
                    fontsize=7)
    return dict(drawn)


def _nearest(items: list[tuple[float, object]], t: float):
    if not items:
        return None
    return min(items, key=lambda tm: abs(tm[0] - t))


def _image(ax, item, title: str) -> None:
    ax.set_title(title, fontsize=9, color="w")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_facecolor("#111")
    if item is None:
        ax.text(0.5, 0.5, f"no {title} in this bag", color="0.7", ha="center", va="center", fontsize=8,
                transform=ax.transAxes)
        return
    m = item[1]
    ch = {"mono8": 1, "rgb8": 3}.get(m.encoding)
    if ch is None:
        ax.text(0.5, 0.5, f"encoding {m.encoding}", color="0.7", ha="center", transform=ax.transAxes)
        return
    img = np.frombuffer(m.data, np.uint8).reshape(m.height, m.step)[:, : m.width * ch]
    img = img.reshape(m.height, m.width, ch) if ch == 3 else img
    ax.imshow(img, cmap="gray" if ch == 1 else None)


def render(data: dict, out_png: str | Path, at: float | None = None) -> dict:
    """Draw the layout's panels from ``data`` (:func:`read_foxglove`) into ``out_png``; the scene at log time
    ``at`` s from the start (default: the scene with the deepest push). Returns the plotted numbers
    (also written beside the PNG as ``.json``). Raises ``ValueError`` if the bag has no ``/viz/scene``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = data.get(SCENE, [])
    if not scenes:
        raise ValueError("no /viz/scene channel: write the Foxglove channels first (docs/visualise.md)")
    t0 = min(tm[0] for items in data.values() for tm in items)
    metrics = data.get(METRICS, [])
    if at is None:
        depth = [(_get(m, "push_depth_mm") or 0.0, t) for t, m in metrics]
        t_at = max(depth)[1] if depth else scenes[len(scenes) // 2][0]
    else:
        t_at = t0 + float(at)
    t_scene, scene = _nearest(scenes, t_at)
    plt.style.use("dark_background")
    fig = plt.figure(figsize=(16, 9), dpi=100)
    gs = fig.add_gridspec(3, 3, height_ratios=[1, 1, 0.7], width_ratios=[1.25, 1.25, 1], hspace=0.32,
                          wspace=0.1,
                          left=0.04, right=0.98, top=0.93, bottom=0.07)
    ax3 = fig.add_subplot(gs[0:2, 0:2], projection="3d")
    drawn = _draw_scene(ax3, scene)
    ax3.set_xlim(-0.5, 0.42)
    ax3.set_ylim(-0.55, 0.55)
    ax3.set_zlim(-0.45, 0.25)
    ax3.set_box_aspect((0.92, 1.1, 0.7), zoom=1.35)
    ax3.view_init(elev=18, azim=28)
    ax3.set_facecolor("#1b1d22")
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z (m)")
    ax3.set_title(f"3D: /viz/scene at t = {t_scene - t0:.2f} s (display frame)", fontsize=10)
    for k, topic in enumerate(_IMAGES):
        _image(fig.add_subplot(gs[k, 2]) if k < 2 else fig.add_subplot(gs[2, 2]),
               _nearest(data.get(topic, []), t_scene),
               topic)
    numbers: dict = {"bag_start": t0, "scene_time_s": t_scene - t0, "scene_entities": drawn, "plots": {}}
    row = gs[2, 0:2].subgridspec(1, len(PLOTS), wspace=0.3)
    for k, (pid, (title, series)) in enumerate(PLOTS.items()):
        ax = fig.add_subplot(row[0, k])
        ax.set_title(title, fontsize=9)
        for path, label in series:
            topic, _, field = path.partition(".")
            pts = [(round(t - t0, 3), _get(m, field)) for t, m in data.get(topic, [])]
            pts = [(t, round(v, 4)) for t, v in pts if isinstance(v, (int, float))]
            if pts:
                ax.plot(*zip(*pts, strict=True), lw=0.8, label=label)
            numbers["plots"].setdefault(pid, {})[label] = pts
        ax.axvline(t_scene - t0, color="0.6", lw=0.6, ls=":")
        ax.set_xlabel("time in bag (s)", fontsize=8)
        ax.tick_params(labelsize=7)
        if len(series) > 1:
            ax.legend(fontsize=6, loc="upper right")
    fig.suptitle("flexsheet in the Foxglove layout's panels — drawn from the bag with matplotlib, not "
                 "Foxglove",
                 fontsize=11)
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=100)
    plt.close(fig)
    out_png.with_suffix(".json").write_text(json.dumps(numbers))
    return numbers


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m flexsheet.viz.preview", description=__doc__.splitlines()[0],
                                 epilog="example:\n  python -m flexsheet.viz.preview run_foxglove.mcap "
                                        "preview.png --at 20",
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bag", help="MCAP file with Foxglove channels")
    ap.add_argument("output", help="output .png (a .json of the plotted numbers is written beside it)")
    ap.add_argument("--at", type=float, default=None, help="scene time, s from the bag start (default: "
                                                           "deepest push)")
    args = ap.parse_args(argv)
    try:
        numbers = render(read_foxglove(args.bag), args.output, args.at)
    except (ValueError, FileNotFoundError) as exc:
        print(f"preview: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.output} (scene at {numbers['scene_time_s']:.2f} s) and "
          f"{Path(args.output).with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
