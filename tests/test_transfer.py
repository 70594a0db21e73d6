"""Transfer functions, colormaps, JSON round trip and pre-integration tables.

Pre-integration entries are checked against a direct numerical evaluation of the emission-
absorption integral (cumulative trapezoid on 200k points along the segment), written here from the
definition; the reuse recurrence (eq. 14) against the direct build of every diagonal.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid, trapezoid

import splinecast as sc
from splinecast.preintegration import preintegrate
from splinecast.transfer import COLORMAPS, TransferFunction, apply_colormap, colormap_table

BAND = [(0.0, 0.0), (0.4, 0.0), (0.5, 0.95), (0.6, 0.1), (0.8, 0.0), (1.0, 0.3)]


@pytest.fixture(scope="module")
def tf():
    return TransferFunction(BAND, domain=(0.0, 1.0), colormap="viridis")


def test_opacity_and_color_interpolate_control_points(tf):
    assert tf.opacity(0.5) == pytest.approx(0.95)
    assert tf.opacity(0.45) == pytest.approx(0.475)
    assert tf.opacity(-5.0) == 0.0 and tf.opacity(7.0) == pytest.approx(0.3)
    assert tf.extinction(0.5) == pytest.approx(-np.log(0.05))
    pts = np.asarray(COLORMAPS["viridis"])
    np.testing.assert_allclose(tf.color(0.0), pts[0, 1:])
    np.testing.assert_allclose(tf.color(1.0), pts[-1, 1:])
    np.testing.assert_allclose(colormap_table("gray", 5)[:, 0], np.linspace(0, 1, 5))


def test_json_round_trip(tmp_path, tf):
    path = tmp_path / "tf.json"
    tf.save(path)
    assert json.loads(path.read_text())["colormap"] == "viridis"
    back = TransferFunction.load(path)
    v = np.linspace(-0.2, 1.2, 301)
    np.testing.assert_array_equal(back.opacity(v), tf.opacity(v))
    np.testing.assert_array_equal(back.color(v), tf.color(v))
    custom = TransferFunction([(0, 0), (1, 1)], (0, 2), colormap=[(0, 1, 0, 0), (1, 0, 0, 1)])
    custom.save(path)
    np.testing.assert_allclose(TransferFunction.load(path).color(1.0), [0.5, 0, 0.5])


def test_bad_inputs_raise_one_line_errors(tmp_path):
    with pytest.raises(sc.ParameterError, match="colormap"):
        TransferFunction([(0, 0)], (0, 1), colormap="nope")
    with pytest.raises(sc.ParameterError, match="opacity"):
        TransferFunction([(0, 2.0)], (0, 1))
    with pytest.raises(sc.ParameterError, match="domain"):
        TransferFunction([(0, 0)], (1, 0))
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(sc.ReadError, match="bad.json") as info:
        TransferFunction.load(bad)
    assert "\n" not in str(info.value)
    with pytest.raises(sc.ReadError, match="no such"):
        TransferFunction.load(tmp_path / "missing.json")


def test_visible_ranges_and_prefix_table_agree_with_dense_sampling(tf):
    assert tf.visible_ranges() == [(0.4, 0.8), (0.8, np.inf)] or tf.visible_ranges() == [
        (0.4, np.inf)]
    prefix = tf.transparency_prefix(64)
    rng = np.random.default_rng(1)
    edges = np.linspace(0.0, 1.0, 65)
    for _ in range(300):
        a, b = np.sort(rng.integers(0, 64, 2))
        values = np.linspace(edges[a], edges[b + 1], 400)
        dense_transparent = not np.any(tf.opacity(values) > 0)
        assert (prefix[b + 1] == prefix[a]) == dense_transparent


def _reference_segment(values, rgb, tau, vf, vb, h):
    """The emission-absorption integral of one segment, from its definition."""
    x = np.linspace(0.0, h, 200_001)
    s = vf + (vb - vf) * x / h
    t = np.interp(s, values, tau)
    c = np.stack([np.interp(s, values, rgb[:, k]) for k in range(3)], axis=-1)
    od = cumulative_trapezoid(t, x, initial=0.0)
    trans = np.exp(-od)
    return np.array([*(trapezoid(c[:, k] * t * trans, x) for k in range(3)), 1 - trans[-1]])


def test_preintegration_entries_match_numerical_integration(tf):
    n, h0 = 48, 0.5
    table = preintegrate(tf, n=n, h0=h0, steps=5)
    values, rgb, tau = tf.sample(n)
    for f, b, k in [(0, 47, 1), (47, 0, 2), (20, 20, 5), (18, 21, 4), (23, 19, 3), (10, 30, 5),
                    (21, 22, 1), (40, 45, 2)]:
        ref = _reference_segment(values, rgb, tau, values[f], values[b], k * h0)
        np.testing.assert_allclose(table.table[k - 1, f, b], ref, atol=2e-6)


def test_reuse_recurrence_gives_the_direct_table(tf):
    direct = preintegrate(tf, n=40, h0=0.25, steps=8, reuse=False)
    reused = preintegrate(tf, n=40, h0=0.25, steps=8, reuse=True)
    assert direct.composited_fraction == 0.0
    assert 0.2 < reused.composited_fraction < 0.6
    np.testing.assert_allclose(reused.table, direct.table, atol=1e-6)


@pytest.mark.parametrize("layout", ["uniform", "exponential"])
def test_reuse_build_matches_numerical_integration_for_both_layouts(tf, layout):
    n, h0, steps = 33, 0.5, 4
    reused = preintegrate(tf, n=n, h0=h0, steps=steps, layout=layout)
    direct = preintegrate(tf, n=n, h0=h0, steps=steps, layout=layout, reuse=False)
    values, rgb, tau = tf.sample(n)
    lengths = h0 * (2.0 ** np.arange(steps) if layout == "exponential"
                    else np.arange(1, steps + 1))
    np.testing.assert_allclose(reused.lengths, lengths)
    if layout == "exponential":
        # Eq. 13: every even diagonal (the main one included) of tables 1..K-1 is composited.
        even = sum(n - abs(d) for d in range(-(n - 1), n) if d % 2 == 0)
        assert reused.composited_fraction == pytest.approx(even * (steps - 1) / (steps * n * n))
        picks = [(j, f, b) for j in (1, 2, 3) for f, b in [(0, 32), (32, 0), (7, 7), (10, 16),
                                                            (25, 13), (14, 16), (20, 18)]]
    else:
        # Eq. 14 composites the diagonals whose offset shares a divisor with k.
        assert 0.2 < reused.composited_fraction < 0.6
        picks = [(k - 1, f, b) for k in (2, 4) for f, b in [(0, 32), (32, 0), (7, 7),
                                                            (10, 16), (25, 13), (14, 16)]]
    assert direct.composited_fraction == 0.0
    np.testing.assert_allclose(reused.table, direct.table, atol=1e-6)
    for j, f, b in picks:
        ref = _reference_segment(values, rgb, tau, values[f], values[b], lengths[j])
        np.testing.assert_allclose(reused.table[j, f, b], ref, atol=2e-6,
                                   err_msg=f"{layout} table {j} entry ({f}, {b})")


def test_bad_layout_raises(tf):
    with pytest.raises(sc.ParameterError, match="layout"):
        preintegrate(tf, n=8, layout="log")


def test_apply_colormap_window_and_background():
    values = np.array([[np.nan, -1.0, 0.5, 3.0]])
    rgba = apply_colormap(values, (0.0, 1.0), "gray", background=(0.1, 0.2, 0.3, 1.0))
    np.testing.assert_allclose(rgba[0, 0], [0.1, 0.2, 0.3, 1.0], atol=1e-7)
    np.testing.assert_allclose(rgba[0, 1, :3], 0.0)
    np.testing.assert_allclose(rgba[0, 2, :3], 0.5, atol=1e-3)
    np.testing.assert_allclose(rgba[0, 3, :3], 1.0)


def _colormap_reference(values, window, colormap, background):
    """The colormapped image by whole-array numpy operations in float64 (nearest of 1024 table
    entries, NaN to the background)."""
    lo, hi = window
    table = colormap_table(colormap, 1024)
    v = np.asarray(values, np.float64)
    u = np.clip((np.nan_to_num(v, nan=lo) - lo) / (hi - lo), 0.0, 1.0)
    rgba = np.empty((*v.shape, 4), np.float32)
    rgba[..., :3] = table[np.rint(u * 1023).astype(np.int64)]
    rgba[..., 3] = 1.0
    rgba[np.isnan(v)] = np.asarray(background, np.float32)
    return rgba


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("colormap", ["viridis", "hot"])
@pytest.mark.parametrize("shape", [(37, 53), (301, 263)])  # one chunk of pixels; several
def test_apply_colormap_matches_the_whole_array_formula(dtype, colormap, shape):
    rng = np.random.default_rng(7)
    values = rng.uniform(-3.0, 13.0, shape).astype(dtype)
    values[rng.random(values.shape) < 0.1] = np.nan
    values[0, :3] = (np.inf, -np.inf, 2.0 + 1.5 * 10 / 1023)  # a tie of the nearest entry
    strided = values[:, ::2]  # not contiguous
    background = (0.1, 0.2, 0.3, 0.4)
    got = apply_colormap(strided, (2.0, 12.0), colormap, background)
    assert got.dtype == np.float32 and got.shape == (*strided.shape, 4)
    np.testing.assert_array_equal(got, _colormap_reference(strided, (2.0, 12.0), colormap,
                                                           background))


@pytest.mark.parametrize("name", ["gray", "bone", "hot", "viridis", "coolwarm", "RdBu_r", "jet",
                                  "magma_r", "Greys", "berlin", "turbo"])
def test_named_colormaps_are_matplotlibs(name):
    """Names resolve through the cmap catalog to matplotlib's colours (an independent library
    holding the same tables)."""
    matplotlib = pytest.importorskip("matplotlib")
    if name not in matplotlib.colormaps:
        pytest.skip(f"matplotlib {matplotlib.__version__} has no {name}")
    x = np.linspace(0.0, 1.0, 256)
    # (matplotlib's tables of the Crameri maps are rounded to 5 decimals, cmap's are not.)
    np.testing.assert_allclose(colormap_table(name, 256), matplotlib.colormaps[name](x)[:, :3],
                               atol=1e-5)


def test_menu_names_and_misspellings():
    assert list(COLORMAPS) == list(sc.transfer.MENU) and sc.transfer.DIVERGING in COLORMAPS
    assert COLORMAPS["gray"].shape == (256, 4)
    np.testing.assert_array_equal(colormap_table("grey", 8), colormap_table("gray", 8))
    assert "viridis" in sc.transfer.colormap_names()
    with pytest.raises(sc.ParameterError, match=r"did you mean viridis"):
        colormap_table("virdis")
    with pytest.raises(sc.ParameterError, match=r"^--colormap 'qqzzqq' is not a known "
                                                r"colormap \(accepted: gray, bone"):
        sc.transfer.check_colormap("qqzzqq", "--colormap")
    # A name stays a name through JSON; the colours are the catalog's.
    tf = TransferFunction([(0, 0), (1, 1)], (0, 1), colormap="cmocean:thermal")
    assert TransferFunction.from_dict(tf.to_dict()).colormap == "cmocean:thermal"


@pytest.mark.parametrize("text, alpha, expected", [
    ("white", False, (1.0, 1.0, 1.0)),
    ("#336699", False, (0.2, 0.4, 0.6)),
    ("0.1,0.2,0.3", False, (0.1, 0.2, 0.3)),
    ([0.0, 1.0, 0.0], False, (0.0, 1.0, 0.0)),
    ("black", True, (0.0, 0.0, 0.0, 1.0)),
    ("#ff000080", True, (1.0, 0.0, 0.0, 128 / 255)),
    ("0,0,0,0.5", True, (0.0, 0.0, 0.0, 0.5)),
    ("transparent", True, (0.0, 0.0, 0.0, 0.0)),
])
def test_parse_color(text, alpha, expected):
    assert sc.transfer.parse_color(text, alpha=alpha) == pytest.approx(expected)


@pytest.mark.parametrize("text, alpha, needle", [
    ("whit", False, "did you mean white"),
    ("1,2,3", False, "accepted: a colour name"),
    ("0,0,0,0.5", False, "R,G,B numbers"),
    ("transparent", False, "is not a colour"),
    ("#12", True, "#RRGGBBAA"),
    (True, False, "is not a colour"),
])
def test_parse_color_refuses_with_the_accepted_forms(text, alpha, needle):
    with pytest.raises(sc.ParameterError, match="^--background .* is not a colour") as info:
        sc.transfer.parse_color(text, "--background", alpha=alpha)
    assert needle in str(info.value) and "\n" not in str(info.value)
