"""The report's figures and the layout drawing: PNG files of the expected size with something
drawn on them, read back with matplotlib."""

from __future__ import annotations

import io
from collections.abc import Callable
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from fleet_sim.config.experiment import Target
from fleet_sim.config.layout import Layout
from fleet_sim.report import figures as figs
from fleet_sim.report.layout_plot import draw_layout

DPI = 110  # figs.png_bytes


def pixels(png: bytes | Path) -> np.ndarray:
    """RGB(A) floats in [0, 1], rows x columns x channels."""
    source = io.BytesIO(png) if isinstance(png, bytes) else png
    image = np.asarray(mpimg.imread(source, format="png"))
    assert image.ndim == 3 and image.shape[2] in (3, 4)
    return image


def colours(image: np.ndarray) -> int:
    """How many distinct RGB colours (8 bits a channel) the image has."""
    rgb = (image[:, :, :3] * 255).round().astype(np.int64)
    return len(np.unique(rgb[:, :, 0] << 16 | rgb[:, :, 1] << 8 | rgb[:, :, 2]))


def assert_drawn(image: np.ndarray, min_share: float = 0.01) -> None:
    """Not blank: a share of pixels away from the background and several colours."""
    rgb = image[:, :, :3]
    share = float((np.abs(rgb - rgb[0, 0]).sum(axis=2) > 0.05).mean())
    assert share > min_share, f"only {share:.2%} of the pixels are drawn"
    assert colours(image) > 5


def assert_size(image: np.ndarray, width_in: float, height_in: float, dpi: int) -> None:
    height, width = image.shape[:2]
    assert abs(width - width_in * dpi) <= 1 and abs(height - height_in * dpi) <= 1, (
        (width, height), (width_in * dpi, height_in * dpi))


def stats_rows(x: str, kpis: list[str]) -> pd.DataFrame:
    rows = [{x: n, "kpi": kpi, "mean": 10.0 * n + i, "ci_low": 9.0 * n + i,
             "ci_high": 11.0 * n + i} for n in (2, 4, 6) for i, kpi in enumerate(kpis)]
    return pd.DataFrame(rows)


def state_means() -> pd.DataFrame:
    return pd.DataFrame({"fleet.size": [2, 4, 6], "state_moving_pct": [70.0, 55.0, 40.0],
                         "state_idle_pct": [10.0, 30.0, 50.0],
                         "state_loading_pct": [20.0, 15.0, 10.0]})


FIGURES: dict[str, tuple[Callable[[], Figure], tuple[float, float]]] = {
    "one KPI": (lambda: figs.kpi_panels({"": stats_rows("fleet.size", ["throughput_per_hour"])},
                                        "fleet.size", ["throughput_per_hour"], [], {"": 4}),
                (4.6, 3.6)),
    "four KPIs, two series, a target": (
        lambda: figs.kpi_panels(
            {"a": stats_rows("fleet.size", ["k1", "k2", "k3", "k4"]),
             "b": stats_rows("fleet.size", ["k1", "k2", "k3", "k4"])},
            "fleet.size", ["k1", "k2", "k3", "k4"], [Target(kpi="k1", at_least=40.0)],
            {"a": 4, "b": None}),
        (4.6 * 3, 3.6 * 2)),
    "state bars": (lambda: figs.state_bars(state_means(), "fleet.size", "states"), (9, 3.8)),
    "incidents": (lambda: figs.incidents(pd.DataFrame({"fleet.size": [2, 4, 6],
                                                       "deadlocks": [0.0, 1.0, 3.0],
                                                       "reroute": [2.0, 5.0, 9.0]}),
                                         "fleet.size"), (8, 3.4)),
    "SOC curves": (lambda: figs.soc_curves(pd.DataFrame({
        "time_s": [0.0, 1800.0, 3600.0] * 2, "agv": [0, 0, 0, 1, 1, 1],
        "soc_pct": [90.0, 70.0, 50.0, 80.0, 60.0, 95.0]}), "SOC"), (9, 3.4)),
    "text page": (lambda: figs.text_page("Title", ["a line of text " * 8] * 6),
                  (8.27, 11.69)),
}


@pytest.mark.parametrize("name", FIGURES)
def test_report_figures_are_drawn_pngs_of_their_size(name: str) -> None:
    build, (width_in, height_in) = FIGURES[name]
    fig = build()
    try:
        image = pixels(figs.png_bytes(fig))
    finally:
        figs.close(fig)
    assert_size(image, width_in, height_in, DPI)
    assert_drawn(image, 0.002 if name == "text page" else 0.01)


def layout_inches(layout: Layout, widest: float, per_inch: float, extra: float
                  ) -> tuple[float, float]:
    """The figure size rule of draw_layout (widest 24 in, 1 in per 6 m) and heat_map."""
    xs = [d["x"] for _, d in layout.graph.nodes(data=True)]
    ys = [d["y"] for _, d in layout.graph.nodes(data=True)]
    span_x = (max(xs) - min(xs)) or 1.0
    span_y = (max(ys) - min(ys)) or 1.0
    width = min(widest, max(6.0, span_x / per_inch))
    return width, max(3.0, width * span_y / span_x) + extra


def test_layout_drawing_is_a_png_file_of_its_size(tiny_layout: Layout, tmp_path: Path) -> None:
    path = draw_layout(tiny_layout, tmp_path / "drawings" / "tiny.png")
    assert path == tmp_path / "drawings" / "tiny.png" and path.read_bytes()[:4] == b"\x89PNG"
    image = pixels(path)
    assert_size(image, *layout_inches(tiny_layout, 24.0, 6.0, 1.0), dpi=130)
    assert_drawn(image)
    assert pixels(figs.layout_png(tiny_layout)).shape == image.shape


def test_heat_map_colours_the_nodes_where_agvs_waited(tiny_layout: Layout) -> None:
    nodes = list(tiny_layout.graph.nodes)
    waited = pd.DataFrame({"node": nodes[:3], "wait_s_per_h": [5.0, 40.0, 120.0]})
    nobody = pd.DataFrame({"node": nodes[:1], "wait_s_per_h": [0.0]})
    images = {}
    for name, waits in (("waited", waited), ("nobody", nobody)):
        fig = figs.heat_map(tiny_layout, waits, name)
        try:
            images[name] = pixels(figs.png_bytes(fig))
            axes = len(fig.axes)
        finally:
            figs.close(fig)
        assert axes == (2 if name == "waited" else 1)  # the colour bar, only with waiting
        assert_size(images[name], *layout_inches(tiny_layout, 14.0, 8.0, 1.2), dpi=DPI)
        assert_drawn(images[name])
    # the colour bar and the coloured nodes: far more colours than the grey track alone
    assert colours(images["waited"]) > 2 * colours(images["nobody"])


def test_image_page_shows_a_png(tiny_layout: Layout) -> None:
    png = figs.layout_png(tiny_layout)
    height, width = pixels(png).shape[:2]
    fig = figs.image_page(png, "Layout")
    try:
        image = pixels(figs.png_bytes(fig))
    finally:
        figs.close(fig)
    assert_size(image, 11, max(3.0, 11 * height / width), DPI)
    assert_drawn(image)


def test_labels_write_node_ids_sized_to_the_node_spacing(warehouse_layout: Layout,
                                                          tmp_path: Path) -> None:
    """`layout --labels`: the warehouse keeps its size, its ids get a font of 6-9 pt (nodes are
    4 m apart), and the drawing holds more dark (text) pixels than without labels; where
    nodes are too close for the smallest font, the figure grows until a label fits its gap."""
    from fleet_sim.report.layout_plot import CHAR_WIDTH_EM, LABEL_PT, label_size

    plain = pixels(draw_layout(warehouse_layout, tmp_path / "plain.png"))
    labelled = pixels(draw_layout(warehouse_layout, tmp_path / "labels.png", labels=True))
    assert plain.shape == labelled.shape
    width, font = label_size(warehouse_layout, 104 / 6, 104.0)
    assert width == pytest.approx(104 / 6) and 6.0 <= font <= LABEL_PT[1]

    def dark(image: np.ndarray) -> int:
        return int((image[:, :, :3].max(axis=2) < 0.25).sum())

    # ~36 dark pixels per 6.8 pt id at 130 dpi; at least 20 per node
    assert dark(labelled) > dark(plain) + 20 * warehouse_layout.graph.number_of_nodes()
    wide, smallest = label_size(warehouse_layout, 6.0, 104.0)  # 6 in: 4 m is 16.6 pt
    assert smallest == pytest.approx(LABEL_PT[0]) and wide > 9.0
    gap_pt = 4.0 * wide / 104.0 * 72
    assert (CHAR_WIDTH_EM * len("A01_04") + 0.5) * smallest <= 0.6 * gap_pt + 1e-6
