"""The layout every Rerun recording of the simulator opens with: a 3D view of the recorded worlds
that fills most of the window, and their plots in tabs beside it.

:func:`world_offsets` places the recorded worlds side by side on a grid (each simulated world has
its own arena at the same coordinates, so drawn on top of each other their terrains and obstacles
would mix); :func:`viewer_blueprint` builds the ``rerun.blueprint`` that frames them.
:class:`~.recorder.RerunRecorder` sends it to every recording it makes: ``evaluate --rerun``,
``--serve`` and training's ``logger=rerun``.
"""

from __future__ import annotations

import math
import os
import uuid
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import rerun.blueprint as rrb

__all__ = ["PLOTS_SHARE", "WORLD_GAP", "ViewShare", "view_shares", "viewer_blueprint", "world_offsets"]

WORLD_GAP = 4.0
"""Free ground between two recorded worlds' walls on the grid [m]."""
PLOTS_SHARE = 0.25
"""Width of the plots' side panel, as a share of the window's [-]; the 3D view has the rest."""


def world_offsets(worlds: Sequence[int], half_size: float) -> dict[int, np.ndarray]:
    """Where each recorded world's arena centre is drawn [m] (x, y, 0): on a grid of ``ceil(sqrt(k))``
    columns, one arena side plus :data:`WORLD_GAP` apart, in the order given."""
    cols = max(1, math.ceil(math.sqrt(len(worlds))))
    pitch = 2 * half_size + WORLD_GAP
    return {w: np.array([(i % cols) * pitch, -(i // cols) * pitch, 0.0]) for i, w in enumerate(worlds)}


def _eye(offsets: dict[int, np.ndarray], half_size: float) -> rrb.EyeControls3D:
    """An orbiting eye south-west of and above the worlds' grid, looking at its centre, far enough back
    that every arena is in view."""
    centres = np.stack(list(offsets.values()))
    lo, hi = centres.min(0) - half_size, centres.max(0) + half_size
    target = 0.5 * (lo + hi)
    extent = float(np.max(hi - lo))
    position = target + extent * np.array([-0.25, -0.75, 0.95])
    return rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=position.tolist(), look_target=target.tolist(),
                             eye_up=[0.0, 0.0, 1.0])


def viewer_blueprint(worlds: Sequence[int], half_size: float, *, training: bool = False) -> rrb.Blueprint:
    """The layout of a recording of ``worlds`` (arena half size ``half_size`` [m]).

    Left, ``1 - PLOTS_SHARE`` of the window's width and its full height: a 3D view of everything
    but the plots, its eye framing the worlds laid out by :func:`world_offsets`. Right: one tab of
    plots (reward, distance, wheel torques) per recorded world, and with ``training`` a first tab
    of the training scalars (``/train``). The blueprint and selection panels start collapsed, and the
    time panel to its one line of play controls and time slider.
    """
    offsets = world_offsets(worlds, half_size)
    scene = rrb.Spatial3DView(origin="/", name="worlds", contents=["+ /**", "- /plots/**", "- /train/**"],
                              eye_controls=_eye(offsets, half_size), line_grid=rrb.LineGrid3D(visible=False))
    tabs = [rrb.TimeSeriesView(origin=f"/plots/world_{w}", name=f"world {w}") for w in worlds]
    if training:
        tabs.insert(0, rrb.TimeSeriesView(origin="/train", name="training"))
    return rrb.Blueprint(
        rrb.Horizontal(scene, rrb.Tabs(*tabs, active_tab=0), column_shares=[1.0 - PLOTS_SHARE, PLOTS_SHARE]),
        rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"), rrb.TimePanel(state="collapsed"),
        auto_views=False)


@dataclass(frozen=True)
class ViewShare:
    """One view of a recording's layout and the share of the viewport it is drawn in."""

    name: str
    kind: str
    """Rerun's view class: ``3D``, ``TimeSeries``, …"""
    origin: str
    share: float
    """Its area over the viewport's [-] (a tab: its container's whole area, while it is shown)."""


def view_shares(path: str | os.PathLike) -> list[ViewShare]:
    """The views of the default layout stored in the ``.rrd`` file ``path``, largest first: what the
    viewer draws, read back from the blueprint without a viewer (the canvas is not in a page's DOM)."""
    from rerun.chunk import RrdReader

    reader = RrdReader(os.fspath(path))
    stores = reader.blueprints()
    if not stores:
        raise ValueError(f"{path}: holds no blueprint")
    rows: dict[str, dict] = {}
    for chunk in reader.stream(store=stores[-1]).to_chunks():
        batch = chunk.to_record_batch()
        row = rows.setdefault(str(chunk.entity_path).lstrip("/"), {})
        for name in batch.schema.names:
            values = [v for v in batch.column(name).to_pylist() if v is not None]
            if values and ":" in name:
                row[name.split(":", 1)[1]] = values[-1][0] if isinstance(values[-1], list) and len(values[-1]) == 1 \
                    else values[-1]
    root = f"container/{uuid.UUID(bytes=bytes(rows['viewport']['root_container']))}"
    out: list[ViewShare] = []

    def walk(key: str, share: float) -> None:
        row = rows.get(key, {})
        if key.startswith("view/"):
            out.append(ViewShare(row.get("display_name", ""), row.get("class_identifier", ""),
                                 row.get("space_origin", ""), share))
            return
        children = row.get("contents") or []
        if isinstance(children, str):
            children = [children]
        kind = row.get("container_kind")  # 1 tabs, 2 horizontal, 3 vertical, 4 grid
        if kind == 1:  # each tab in the whole area
            weights = [1.0] * len(children)
        elif kind in (2, 3):
            shares = row.get("col_shares" if kind == 2 else "row_shares") or [1.0] * len(children)
            weights = [float(v) / float(sum(shares)) for v in shares]
        else:
            weights = [1.0 / len(children)] * len(children)
        for child, weight in zip(children, weights):
            walk(child, share * weight)

    walk(root, 1.0)
    return sorted(out, key=lambda v: -v.share)
