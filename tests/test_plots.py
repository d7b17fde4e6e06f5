"""Report charts: well-formed SVG, correct data URIs, no NaN trouble."""

import base64
import io
import xml.etree.ElementTree as ET

import numpy as np
from PIL import Image

from curate.report.plots import bar_chart, camera_map, colormap, jpeg_data_uri, line_chart, png_data_uri


def test_svgs_parse_and_hold_their_data():
    s = line_chart({"energy": ([1, 2, 3], [10.0, 12.5, 13.0]), "random": ([1, 2, 3], [9, 9.5, 11])}, "E", "step", "E")
    root = ET.fromstring(s)
    assert root.tag.endswith("svg") and len(root.findall(".//{http://www.w3.org/2000/svg}polyline")) == 2
    s = camera_map(np.random.default_rng(0).normal(size=(20, 2)), np.ones((20, 2)), [1, 5], "cams",
                   extra_xy=np.zeros((2, 2)))
    ET.fromstring(s)
    assert s.count('r="3.5"') == 2
    s = bar_chart(["energy", "random", "fvs"], [17.5, 17.2, np.nan], [0, 0.3, 0], "PSNR", "dB")
    ET.fromstring(s)
    assert "17.5" in s
    ET.fromstring(line_chart({"empty": ([], [])}, "t", "x", "y"))  # degenerate inputs still draw


def test_colormap_and_data_uris():
    a = np.array([[0.0, 1.0], [np.nan, 0.5]])
    rgb = colormap(a)
    assert rgb.shape == (2, 2, 3) and rgb.dtype == np.uint8 and tuple(rgb[1, 0]) == (225, 225, 225)
    uri = png_data_uri(rgb, scale=4)
    im = Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1])))
    assert im.size == (8, 8)
    uri = jpeg_data_uri(np.zeros((300, 600, 3), np.uint8), max_side=100)
    assert Image.open(io.BytesIO(base64.b64decode(uri.split(",", 1)[1]))).size == (100, 50)
