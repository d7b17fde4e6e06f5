"""Report charts: well-formed SVG, correct data URIs, no NaN trouble."""

import base64
import io
import xml.etree.ElementTree as ET

import numpy as np
from PIL import Image

from curate.html.charts import bar_chart, camera_map, line_chart, text_of
from curate.html.plots import colormap, jpeg_data_uri, png_data_uri


def test_charts_are_inline_svg_holding_their_data():
    s = line_chart({"energy": ([1, 2, 3], [10.0, 12.5, 13.0]), "random": ([1, 2, 3], [9, 9.5, 11])}, "E", "step", "E")
    root = ET.fromstring(s)
    assert root.tag.endswith("svg") and "http://" not in s.replace("http://www.w3.org", "")
    assert "energy" in text_of(s) and "random" in text_of(s)             # the legend names both series
    ET.fromstring(line_chart({"empty": ([], [])}, "t", "x", "y"))          # degenerate inputs still draw
    ET.fromstring(line_chart({"nan": ([1, 2, 3], [np.nan, 1.0, np.inf])}, "t", "x", "y"))


def test_bar_values_sit_above_their_error_bars_and_a_cut_axis_is_said():
    s = bar_chart(["selection", "random", "fvs"], [25.1, 24.8, np.nan], [0, 0.3, 0], "PSNR", "dB")
    ET.fromstring(s)
    t = text_of(s)
    assert "25.10" in t and "24.80" in t and "n/a" in t and "nan" not in t.lower()
    # bars near 25 dB: the axis is cut, and says so
    assert "starts at" in t
    assert "starts at" not in text_of(bar_chart(["a", "b"], [2.0, 1.0]))  # far apart: from 0, nothing to say


def test_camera_map_legend_shows_each_mark_as_drawn():
    s = camera_map(np.random.default_rng(0).normal(size=(20, 2)), np.ones((20, 2)), [1, 5], "cams",
                   extra_xy=np.zeros((2, 2)))
    ET.fromstring(s)
    assert all(w in text_of(s) for w in ("pool", "chosen", "held out"))
    # held-out views are hollow squares, in the map and in its legend alike
    from matplotlib.colors import to_rgba
    from curate.html.charts import camera_map_figure
    fig, ax = camera_map_figure(np.zeros((4, 2)) + [[0, 0], [1, 0], [0, 1], [1, 1]], np.ones((4, 2)), [1], "c",
                                extra_xy=[[0.5, 0.5]])
    leg = {t.get_text(): h for t, h in zip(ax.get_legend().get_texts(), ax.get_legend().legend_handles)}
    drawn = [c for c in ax.collections if c.get_label() == "held out"][0]
    for art in (leg["held out"], drawn):
        fc = art.get_facecolor()
        assert len(fc) == 0 or to_rgba(fc[0])[3] == 0.0                    # hollow
        assert len(art.get_paths()[0].vertices) == 5                       # a square (closed: 4 corners + 1)
    assert to_rgba(leg["chosen"].get_facecolor()[0])[3] == 1.0           # chosen views: filled dots


def test_colormap_and_data_uris():
    a = np.array([[0.0, 1.0], [np.nan, 0.5]])
    rgb = colormap(a)
    assert rgb.shape == (2, 2, 3) and rgb.dtype == np.uint8 and tuple(rgb[1, 0]) == (225, 225, 225)
    uri = png_data_uri(rgb, scale=4)
    im = Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1])))
    assert im.size == (8, 8)
    uri = jpeg_data_uri(np.zeros((300, 600, 3), np.uint8), max_side=100)
    assert Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1]))).size == (100, 50)
