"""The region figure of the local model: drawn from a real local run, refused for a run without regions."""

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.studies.figures import figure_2d_object, figure_regions


def test_region_figure_of_a_local_run(tmp_path):
    tr = tg.explore(tg.sim.paper_objects_2d()["C"], mode="visual-tactile", regions=3, max_steps=12, progress=False)
    assert np.asarray(tr.region_correlation).shape == (tr.n_steps, 3)
    figure_regions(tr, tmp_path / "regions.png", "C")
    assert (tmp_path / "regions.png").stat().st_size > 10_000
    plain = tg.explore(tg.sim.paper_objects_2d()["C"], mode="visual-tactile", max_steps=3, progress=False)
    with pytest.raises(ValueError, match="no similarity per region"):
        figure_regions(plain, tmp_path / "x.png")


@pytest.fixture(scope="module")
def short_pair(tmp_path_factory):
    """Both modes on object D for a few steps, with their logs (for the early snapshots)."""
    out = tmp_path_factory.mktemp("pair")
    scene = tg.sim.paper_objects_2d()["D"]
    pair = {m: tg.explore(scene, mode=m, max_steps=14, log=out / f"{m}.gpioius", progress=False)
            for m in ("visual-tactile", "tactile")}
    return scene, pair, out


def _renderer(fig):
    """A renderer for a figure the figure functions already closed (closing detaches pyplot's canvas)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    return fig.canvas.get_renderer()


def _tick_texts(fig):
    return [t.get_text() for ax in fig.axes for t in ax.get_xticklabels() + ax.get_yticklabels()]


def test_fig4_keeps_legends_off_the_data_and_shows_both_modes_early(short_pair, tmp_path):
    from torch_gpioius.studies.simulate import _snapshot

    scene, pair, logs = short_pair
    early = {m: _snapshot(logs / f"{m}.gpioius", pair[m], 0.1 * float(pair["tactile"].travel[-1])) for m in pair}
    fig = figure_2d_object("D", scene, pair, tmp_path / "fig4.png", early=early)
    renderer = _renderer(fig)
    data_axes = [ax for ax in fig.axes if ax.images or len(ax.lines) > 2]
    assert len(data_axes) >= 6                                      # 2 x 2 maps and 2 transition panels
    assert not any(ax.get_legend() for ax in fig.axes)             # no legend inside any panel
    for legend in fig.legends:
        box = legend.get_window_extent(renderer)
        assert not any(box.overlaps(ax.get_window_extent(renderer)) for ax in data_axes)
    titles = [ax.get_title() for ax in fig.axes]
    assert sum("at 10 % of the travel" in t for t in titles) == 2 and sum(": final" in t for t in titles) == 2
    assert not any("times" in t for t in _tick_texts(fig))          # no "2x10^0" minor tick labels
    # issue 35, item 14: the true shape is outlined (its fill vanished into the variance map) and every marker kind
    # has a legend entry, the fraction markers included
    legend_texts = [t.get_text() for lg in fig.legends for t in lg.get_texts()]
    assert "true inner shape" in legend_texts and any(t.startswith("H at 10 / 25 / 50 %") for t in legend_texts)
    outlines = [p for ax in fig.axes for p in ax.patches if p.get_label() == "true inner shape"]
    assert outlines and all(p.get_linewidth() >= 1.5 and p.get_edgecolor()[3] == 1.0 for p in outlines)
    # a "touched pieces" curve is drawn only where it differs from the whole estimate's (it hid under it)
    for ax in fig.axes:
        for line in ax.lines:
            if "touched pieces" in line.get_label():
                whole = next(ln for ln in ax.lines if ln.get_label() == line.get_label().split(",")[0])
                assert not np.allclose(np.interp(whole.get_xdata(), line.get_xdata(), line.get_ydata()),
                                       whole.get_ydata())


def test_fraction_labels_never_overprint(tmp_path):
    """10, 25 and 50 % of a short run lie close together; their labels printed as "1025 %50 %"."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from torch_gpioius.studies.figures import fraction_labels

    fig, ax = plt.subplots(figsize=(4, 3))
    ax.set_xlim(0, 3.0)
    labels = fraction_labels(ax, [0.09, 0.23, 0.47], ["10 %", "25 %", "50 %"])
    renderer = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for t in labels]
    assert all(not a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])
    # issue 35, item 13: on fig4_D "10 %" and "25 %" did not overprint but touched ("10 %25 %"); keep a gap
    gap = 0.4 * 7 * fig.dpi / 72
    same_row = [(a, b) for i, a in enumerate(boxes) for b in boxes[i + 1:] if abs(a.y0 - b.y0) < 1]
    assert all(b.x0 - a.x1 >= gap - 1e-6 or a.x0 - b.x1 >= gap - 1e-6 for a, b in same_row)
    plt.close(fig)


def test_fig10_with_one_object_keeps_its_title_and_legend_inside(short_pair, tmp_path):
    """Issue 35, item 12: with one object the title and the legend ran off both edges."""
    from torch_gpioius.studies.figures import figure_similarity

    _, pair, _ = short_pair
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = figure_similarity({"E": pair}, tmp_path / "fig10.png", "Similarity transitions (cf. Fig. 10)")
    canvas = FigureCanvasAgg(fig)                      # the figure was closed after saving
    canvas.draw()
    renderer = canvas.get_renderer()
    width = fig.get_size_inches()[0] * fig.dpi
    for artist in [fig._suptitle, *fig.legends]:
        box = artist.get_window_extent(renderer)
        assert box.x0 >= 0 and box.x1 <= width, artist


def test_fig5_gives_each_object_its_own_panel_and_band(short_pair, tmp_path):
    from torch_gpioius.studies.figures import figure_similarity

    scene, pair, _ = short_pair
    fig = figure_similarity({"A": pair, "D": pair}, tmp_path / "fig5.png")
    bands = [len([c for c in ax.collections if c.get_label().startswith("95 %")]) for ax in fig.axes]
    assert max(bands) <= 1 and len([ax for ax in fig.axes if ax.get_title().startswith("object")]) == 2


def test_paired_figure_labels_every_panel_with_plain_numbers(tmp_path):
    from torch_gpioius.studies.study_figures import figure_paired

    rows = [{"object": o, "mode": m, "seed": s, "final_hausdorff": v}
            for o, base in (("A", 0.005), ("B", 0.1)) for m, f in (("tactile", 1.0), ("visual-tactile", 1.9))
            for s, v in enumerate(base * f * np.array([1.0, 1.05, 0.97]))]
    fig = figure_paired(rows, tmp_path / "p.png")
    _renderer(fig)
    for ax in fig.axes:
        assert ax.get_ylabel()
        shown = [t.get_text() for t in ax.get_yticklabels() if t.get_text()]
        assert len(shown) >= 2 and not any("times" in t for t in shown), shown   # A spans 0.5-1 cm: < a decade


def test_svg_curves_are_millimetres_upright(short_pair, tmp_path):
    import re

    from torch_gpioius.io.export import export_run

    _, _, logs = short_pair
    export_run(logs / "visual-tactile.gpioius", tmp_path / "d.svg")
    text = (tmp_path / "d.svg").read_text()
    width = float(re.search(r'width="([\d.]+)mm"', text).group(1))
    box = [float(v) for v in re.search(r'viewBox="([^"]+)"', text).group(1).split()]
    assert width == pytest.approx(box[2], rel=1e-3) and 50 < width < 1000      # a ~0.2 m shape: ~200 mm wide


def test_a_log_panel_with_no_estimate_says_so_instead_of_failing(tmp_path):
    """Every run of an object can fail before any estimate (its series are NaN): the study's figures must still be
    written (a log axis over no positive data raised and lost the whole aggregation once)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from torch_gpioius.studies.figures import log_axis

    fig, ax = plt.subplots()
    ax.plot([0.0, 1.0], [float("nan"), float("nan")])
    log_axis(ax)
    assert ax.get_yscale() == "linear" and any("no estimate" in t.get_text() for t in ax.texts)
    fig.savefig(tmp_path / "empty.png")
    fig, ax = plt.subplots()
    ax.plot([0.0, 1.0], [0.5, 2.0])
    log_axis(ax)
    assert ax.get_yscale() == "log"


@pytest.mark.parametrize("values", [(3.9, 4.6), (3.95, 4.05), (12.0, 13.5), (0.21, 0.26)])
def test_a_narrow_log_panel_has_at_least_two_ticks_to_read_from(values):
    """Issue 51, item 30: MuJoCo's fig9 Hausdorff panel (3.9-4.6 cm) had a single y tick."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from torch_gpioius.studies.figures import log_axis

    fig, ax = plt.subplots()
    ax.plot([0.0, 0.5, 1.0], [values[0], np.mean(values), values[1]])
    log_axis(ax)
    fig.canvas.draw()
    lo, hi = ax.get_ylim()
    shown = [t for t in ax.get_yticks() if lo <= t <= hi]
    assert len(shown) >= 2, (values, shown)
    plt.close(fig)


def test_fig5_legend_matches_what_is_drawn(short_pair, tmp_path):
    """Issue 35, item 15: the legend's line styles did not match the per-object colours (and showed the dashed
    reference as a solid line)."""
    from torch_gpioius.studies.figures import figure_similarity

    _, pair, _ = short_pair
    fig = figure_similarity({"A": pair, "D": pair}, tmp_path / "fig5.png")
    handles = fig.legends[0].legend_handles
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    dashed = [h for h, lab in zip(handles, labels) if "reference" in lab]
    assert dashed and dashed[0].get_linestyle() == "--"
    drawn = {ln.get_color() for ax in fig.axes for ln in ax.lines if ln.get_label() in ("correlation", "paper's ratio")}
    assert len(drawn) == 2                                   # one colour per object ...
    assert not any(getattr(h, "get_color", lambda: None)() in drawn for h in handles)   # ... none claimed by the key


def test_fig9_tick_labels_do_not_run_together(tmp_path):
    """Issue 35, item 17: fig9's 3-D axes had ten tick labels a side, running together."""
    import torch_gpioius as tg
    from torch_gpioius.sim.forcefield import sphere_scene
    from torch_gpioius.studies.figures import figure_3d_object

    scene = sphere_scene()
    pair = {m: tg.explore(scene, mode=m, max_travel=0.02, metrics_every=100) for m in ("visual-tactile", "tactile")}
    fig = figure_3d_object("S", scene, pair, tmp_path / "fig9.png")
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    for ax in [a for a in fig.axes if hasattr(a, "zaxis")]:
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            boxes = [t.get_window_extent(renderer) for t in axis.get_ticklabels() if t.get_visible() and t.get_text()]
            assert len(boxes) <= 6
            assert not any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])
    # issue 51, item 30: the 3-D panels were small in a wide canvas, the dark estimate hard to tell from the grey wire
    # of the true shape, and the cover was not drawn
    panels = [a for a in fig.axes if hasattr(a, "zaxis")]
    width, height = fig.get_size_inches() * fig.dpi
    assert all(a.get_window_extent(renderer).width > 0.4 * width for a in panels)
    from matplotlib.colors import to_rgba

    legend = {t.get_text() for lg in fig.legends for t in lg.get_texts()}
    assert {"true inner surface (green wire)", "cover (outer surface)"} <= legend
    for ax in panels:
        wire, skin, estimate = ax.collections[1], ax.collections[0], ax.collections[2]
        assert to_rgba(wire.get_edgecolor()[0])[1] > to_rgba(wire.get_edgecolor()[0])[0]     # green
        assert skin.get_facecolor()[0][3] > 0 and skin.get_facecolor()[0][2] > 0.8            # the pale blue cover
        lightest = min(np.mean(c[:3]) for c in estimate.get_facecolor())
        assert lightest > 0.25                           # the certain end of the map is no darker than magenta
    assert all(a.get_xlabel() for a in fig.axes if not hasattr(a, "zaxis") and a.lines)


def test_svg_curves_are_strokes_with_axes(short_pair, tmp_path):
    """Issue 51, item 30: `curves/*.svg` were black filled shapes without axes."""
    import re

    from torch_gpioius.io.export import export_run

    _, _, logs = short_pair
    export_run(logs / "visual-tactile.gpioius", tmp_path / "d.svg")
    text = (tmp_path / "d.svg").read_text()
    estimate = re.search(r'<g id="estimate" fill="none" stroke="#d62728"[^>]*>(.*?)</g>', text, re.S).group(1)
    assert estimate.count("<path") >= 1 and "fill=" not in estimate
    axes = re.search(r'<g id="axes"[^>]*>(.*?)</g>', text, re.S).group(1)
    assert "x [mm]" in axes and "y [mm]" in axes and axes.count("<text") >= 6
