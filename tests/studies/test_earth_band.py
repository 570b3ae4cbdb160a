"""Issue 17 item 6: ``sunsim earth-study``, the band / glint / cloud Earth study and its results page.

No rendering here: the decomposition's arithmetic is checked on tiny synthetic cases against values worked
by hand, the command's refusals with the renderer replaced, and the page on a hand-made results dict
whose numbers are drawn at random (fixed seed), so a number on the page can only have come from it.
"""
import json
import re

import numpy as np
import pytest

from simcore.cli import main
from simcore.studies import earth_band as eb
from simcore.studies import earth_band_page as ep
from simcore.studies.reproduce import FailedCheckError


def _rot_x(deg):
    """Unit vectors (N, 3): +z turned by ``deg`` (N,) about x."""
    a = np.radians(np.asarray(deg, float))
    return np.column_stack([np.zeros_like(a), -np.sin(a), np.cos(a)])


# ---------------------------------------------------------------------------------------------- arithmetic
def test_effect_by_hand():
    # epochs: two that count, one without an estimate (NaN), one in eclipse (huge values that must not count)
    err_with = np.array([1.0, 7.0, np.nan, 90.0])
    err_without = np.array([1.0, 1.0, 2.0, 90.0])
    s_with = _rot_x([30.0, 40.0, 0.0, 170.0])
    s_with[2] = np.nan
    s_without = _rot_x([0.0, 0.0, 0.0, 0.0])
    sunlit = np.array([True, True, True, False])
    e = eb.effect(err_with, err_without, s_with, s_without, sunlit)
    assert e["n"] == 2
    assert e["rms_with_deg"] == pytest.approx(5.0)                      # sqrt((1 + 49) / 2)
    assert e["rms_without_deg"] == pytest.approx(1.0)
    assert e["rms_change_deg"] == pytest.approx(4.0)
    assert e["quadrature_deg"] == pytest.approx(np.sqrt(24.0))          # sqrt(5^2 - 1^2)
    assert e["own_rms_deg"] == pytest.approx(np.sqrt(1250.0))           # sqrt((30^2 + 40^2) / 2)
    assert e["own_max_deg"] == pytest.approx(40.0)
    # an effect that removes error adds nothing in quadrature
    assert eb.effect(err_without, err_with, s_without, s_with, sunlit)["quadrature_deg"] == 0.0


def test_error_stats_by_hand():
    s = eb.error_stats(np.array([3.0, 4.0, np.nan, 100.0]), np.array([True, True, True, False]))
    assert (s["n_sunlit"], s["n_invalid"]) == (3, 1)
    assert s["mean_deg"] == pytest.approx(3.5)
    assert s["rms_deg"] == pytest.approx(np.sqrt(12.5))
    assert s["max_deg"] == 4.0
    assert s["p95_deg"] == pytest.approx(3.95)                          # linear between 3 and 4 at 95 %


def test_decomposition_pairs_and_pools():
    sunlit = np.array([True, True])
    up = _rot_x([0.0, 0.0])
    # per truth: each estimator's error and estimate; the estimate angle about x is the error here
    angle = {("A", "band"): [1.0, 1.0], ("B", "band"): [1.0, 4.0], ("C1", "band"): [2.0, 2.0],
             ("C2", "band"): [6.0, 4.0], ("C1", "toms2005"): [5.0, 5.0], ("C2", "toms2005"): [3.0, 3.0],
             ("C1", "ceres2018-all"): [2.0, 2.0], ("C2", "ceres2018-all"): [6.0, 4.0]}
    errors, estimates = {}, {}
    for (t, m), a in angle.items():
        for est in eb.MODEL_ESTIMATORS:
            errors[(t, m, est)] = np.array(a)
            estimates[(t, m, est)] = _rot_x(a)
    for t in ("A", "B", "C1", "C2"):           # a model-free estimator, unchanged by anything
        errors[(t, eb.NO_MODEL, "wls")] = np.array([2.0, 2.0])
        estimates[(t, eb.NO_MODEL, "wls")] = up
    d = eb.decomposition(errors, estimates, sunlit, [1, 2])
    g = d["glint"]["model_albedo"]                                      # B [1, 4] against A [1, 1]
    assert g["rms_with_deg"] == pytest.approx(np.sqrt(8.5)) and g["own_max_deg"] == pytest.approx(3.0)
    c = d["clouds"]["model_albedo"]             # C1, C2 pooled [2, 2, 6, 4] against B twice [1, 4, 1, 4]
    assert c["n"] == 4
    assert c["rms_with_deg"] == pytest.approx(np.sqrt(60.0 / 4))
    assert c["rms_without_deg"] == pytest.approx(np.sqrt(34.0 / 4))
    assert c["own_rms_deg"] == pytest.approx(np.sqrt((1 + 4 + 25 + 0) / 4))
    m = d["map_toms2005"]["model_albedo+gain"]   # [5, 5, 3, 3] against the band's [2, 2, 6, 4]
    assert m["own_rms_deg"] == pytest.approx(np.sqrt((9 + 9 + 9 + 1) / 4))
    assert m["quadrature_deg"] == pytest.approx(np.sqrt((68 - 60) / 4))
    assert d["map_ceres2018-all"]["model_albedo"]["own_max_deg"] == pytest.approx(0.0, abs=1e-6)
    assert d["glint"]["wls"]["own_rms_deg"] == 0.0 and "wls" not in d["map_toms2005"]


def test_glint_on_the_diode_nearest_nadir():
    normals = np.array([[1, 0, 0], [-1, 0, 0], [0, 0, 1], [0, 0, -1]], float)
    live = np.array([True, True, False, True])              # the +z diode is dead
    nadir = np.array([[0.6, 0.0, 0.8], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    glint = np.array([[13.661, 1.0, 99.0, 2.0], [5.0, 5.0, 5.0, 27.322], [1.0, 2.0, 3.0, 4.0]])
    k, pct = eb.glint_on_nadir_diode(glint, normals, nadir, live, np.array([True, True, False]), 1366.1)
    assert k.tolist() == [0, 3, 0]                           # +z would be nearest first, but it is dead
    np.testing.assert_allclose(pct[:2], [1.0, 2.0])
    assert np.isnan(pct[2])                                  # eclipse


def test_onboard_prediction_takes_a_band_map_name():
    from simcore.radiometry.band import band_maps
    from simcore.radiometry.onboard import predict_albedo_effective
    from scenes.config import SatelliteConfig
    cfg = SatelliteConfig.load("tilt0_fov90")
    r = 6371e3 + 700e3
    geometry = {"r_sat_ecef_m": np.array([[r, 0, 0], [0, r, 0]]), "r_sun_ecef_m": np.array([[1.5e11, 0, 0]] * 2),
                "R_ecef_from_gcrs": np.stack([np.eye(3)] * 2)}
    R = np.stack([np.eye(3)] * 2)
    by_name = predict_albedo_effective(geometry, R, cfg, "band", backend="numpy")
    np.testing.assert_array_equal(by_name, predict_albedo_effective(geometry, R, cfg, band_maps()[1], backend="numpy"))
    assert by_name.max() > 0


# ---------------------------------------------------------------------------------------------- the command
BAD = [(["--wind", "-1"], "--wind"), (["--wind", "nan"], "--wind"), (["--cloud-seeds", "1", "1"], "repeats"),
       (["--cloud-seeds", "-3"], "seed")]


@pytest.mark.parametrize("extra, words", BAD)
def test_bad_input_is_one_line_before_anything(tmp_path, capsys, monkeypatch, extra, words):
    monkeypatch.setattr(eb, "execute", lambda *a, **k: pytest.fail("rendered despite bad input"))
    folder = tmp_path / "runs"
    assert main(["earth-study", "--span", "short", "--folder", str(folder), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err and "Traceback" not in err
    assert not folder.exists()


def test_an_unknown_span_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["earth-study", "--span", "week", "--folder", str(tmp_path / "runs")])
    assert exc.value.code == 2 and "invalid choice: 'week'" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()
    with pytest.raises(eb.InvalidInputError, match="--span"):
        eb.check_inputs("week", 7.0, [1])


def test_an_existing_failed_run_is_refused_before_any_rendering(tmp_path, capsys, monkeypatch):
    folder = tmp_path / "runs"
    folder.mkdir()
    failed = eb.run_options("tilt20_fov70", str(folder), "B", span="short").output
    open(failed, "w").close()
    monkeypatch.setattr(eb, "read_check", lambda path: {"pass": path != failed})
    monkeypatch.setattr(eb, "execute", lambda *a, **k: pytest.fail("rendered before refusing"))
    assert main(["earth-study", "--span", "short", "--folder", str(folder), "--page", str(tmp_path / "page")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "tilt20_fov70:B" in err and "--allow-failed-checks" in err
    assert not (tmp_path / "page").exists() and sorted(p.name for p in folder.iterdir()) == [failed.split("/")[-1]]


def test_a_run_failing_now_stops_before_the_page(tmp_path, monkeypatch):
    written = []

    def fake_execute(opts, log=None):
        open(opts.output, "w").close()
        written.append(opts.output)
    monkeypatch.setattr(eb, "execute", fake_execute)
    monkeypatch.setattr(eb, "read_check", lambda path: {"pass": "clouds" not in path})
    with pytest.raises(FailedCheckError) as exc:
        eb.earth_study(str(tmp_path / "runs"), span="short", page_folder=str(tmp_path / "page"), log=lambda m: None)
    assert len(written) == 6                                 # 2 configurations x truths A, B, C1
    assert "tilt0_fov90:C1" in str(exc.value) and "tilt20_fov70:C1" in str(exc.value)
    assert not (tmp_path / "page").exists()


# ---------------------------------------------------------------------------------------------- the page
def synthetic_results(seed=3, failed=()):
    """Return a results dict shaped as earth_study() writes it, with random figures."""
    rng = np.random.default_rng(seed)
    f = lambda lo=0.1, hi=9.0: float(rng.uniform(lo, hi))  # noqa: E731
    runs = {f"{c}:{t}": {"file": f"{c}_day_spin1.9_band_{t}.nc", "check": {"pass": f"{c}:{t}" not in failed,
                                                                         "tests": []},
                         "check_pass": f"{c}:{t}" not in failed}
            for c in eb.CONFIGS for t in ("A", "B", "C1")}
    places = {name: {"band_clear": f(0, 1), "ceres_clear": f(0, 1), "toms": f(0, 1)}
              for name in ("ocean (0.5N 150.5W)", "vegetation (3.5S 62.5W)", "Sahara (23.5N 10.5E)", "snow (75.5N 40.5W)")}
    headline = {"diode": "BPW34FS (proxy: BPV23F)", "places": places,
                "band_vs_toms": {c: f(-0.9, 2.0) for c in ("water", "forest", "urban", "barren", "snow_ice")}}
    stats = lambda: {"n_sunlit": int(rng.integers(100, 5000)), "n_invalid": int(rng.integers(0, 50)),  # noqa: E731
                     "mean_deg": f(), "rms_deg": f(), "p95_deg": f(), "max_deg": f(5, 20)}
    eff = lambda: {"n": int(rng.integers(100, 5000)), "rms_with_deg": f(), "rms_without_deg": f(),  # noqa: E731
                   "rms_change_deg": f(-3, 3), "quadrature_deg": f(), "own_rms_deg": f(), "own_max_deg": f()}
    configs = {}
    for c in eb.CONFIGS:
        errors = {t: {eb.NO_MODEL: {"wls": stats(), "smart_select": stats()},
                      **{m: {e: stats() for e in eb.MODEL_ESTIMATORS} for m in eb.ONBOARD_MAPS}}
                  for t in ("A", "B", "C1")}
        effects = {**{f"map_{m}": {e: eff() for e in eb.MODEL_ESTIMATORS} for m in ("toms2005", "ceres2018-all")},
                   "glint": {e: eff() for e in ("wls", *eb.MODEL_ESTIMATORS)},
                   "clouds": {e: eff() for e in ("wls", *eb.MODEL_ESTIMATORS)}}
        configs[c] = {"dead": [0] if c != "tilt0_fov90" else [], "period_s": 5871.0, "errors": errors,
                      "effects": effects,
                      "glint_nadir": {"max_pct": f(), "mean_pct": f(), "p95_pct": f(), "t_s": f(0, 86400),
                                      "diode": int(rng.integers(0, 6)), "lat_deg": f(-90, 90), "lon_deg": f(-180, 180),
                                      "rendered_pct": f(), "rendered_se_pct": f(0, 1)}}
    return {"span": "day", "start": "2016-07-02T00:00:00Z", "duration_s": 86400.0,
            "settings": {"step_s": 1.0, "spin_rate_deg_s": 1.9, "diode": "BPW34FS", "e_sun_w_m2": 1366.1,
                         "wind_m_s": 7.0, "cloud_seeds": [1], "truth_map": "band", "onboard_maps": list(eb.ONBOARD_MAPS),
                         "lag_steps": 1, "hanning_window": 181},
            "truths": dict(eb.TRUTHS), "allow_failed_checks": bool(failed), "runs": runs, "headline": headline,
            "configs": configs}


# References that carry digits but are not figures: configuration, map and diode names, file names.
ALLOWED = [r"tilt\d+_fov\d+", r"toms2005", r"ceres2018-all", r"BPW34FS", r"ESTCube-1", r"CERES 2018", r"TOMS 2005",
           r"m\^2", r"\w+\.png", r"\bp95\b", r"\bC1\b", r"sqrt\(with\^2 - without\^2\)", r"issue 17"]


def unsourced_digits(marked_text):
    text = re.sub(r"⟦[^⟧]*⟧", " ", marked_text)
    for pat in ALLOWED:
        text = re.sub(pat, " ", text)
    return [text[max(0, m.start() - 40): m.end() + 40] for m in re.finditer(r"\d", text)]


def test_every_number_on_the_page_comes_from_results_json(tmp_path):
    res = synthetic_results()
    text, sources = ep.render_page(res, ["errors_tilt0_fov90.png"], marked=True)
    assert unsourced_digits(text) == []
    F = ep.StudyFigures(res)
    for _, src in sources:
        kind, _, where = src.partition(":")
        if kind == "results" and "(key" not in where:
            assert F.get(where) is not None, src
        else:
            assert kind in ("results", "derived", "issue"), src
    # the issue's estimates are on the page, labelled, and the results' own numbers beside them
    plain, _ = ep.render_page(res)
    assert "issue's estimate" in plain
    for key in ("ocean_band", "barren_vs_toms", "toms_rms_deg", "clouds_rms_deg"):
        assert f"issue: {ep.ISSUE[key][1]}" in {s for _, s in sources}
    c = res["configs"]["tilt0_fov90"]
    assert f"{c['errors']['C1']['toms2005']['model_albedo+gain']['rms_deg']:.2f}" in plain
    assert f"{c['effects']['clouds']['model_albedo+gain']['own_rms_deg']:.2f}" in plain
    assert f"{100 * res['headline']['band_vs_toms']['barren']:+.0f}" in plain
    # written to a folder: the page the study writes is this text
    (tmp_path / "a.png").write_bytes(b"")
    ep.write_page(res, str(tmp_path))
    assert (tmp_path / "README.md").read_text() == ep.render_page(res, ["a.png"])[0]


def test_numbers_from_a_failed_run_are_marked():
    res = synthetic_results(failed=("tilt20_fov70:C1",))
    text, _ = ep.render_page(res)
    rows = [ln for ln in text.splitlines() if ln.startswith("| C1 |")]
    marked = [ln for ln in rows if ep.FAILED_MARK in ln]
    assert len(marked) == len(rows) // 2 > 0                   # tilt20_fov70's C1 rows, not the cube's
    # truths A and B of tilt20_fov70 passed their checks: their rows are not marked
    assert not any(ep.FAILED_MARK in ln for ln in text.splitlines() if ln.startswith(("| A |", "| B |")))
    assert "**FAIL**" in text and "tilt20_fov70:C1" in text


@pytest.mark.parametrize("toms, clouds, words", [(3.0, 1.0, "more than the cloud weather"),
                                                 (0.5, 1.0, "less than the cloud weather")])
def test_the_verdict_follows_the_numbers(toms, clouds, words):
    res = synthetic_results()
    eff = res["configs"]["tilt0_fov90"]["effects"]
    eff["map_toms2005"]["model_albedo+gain"]["own_rms_deg"] = toms
    eff["clouds"]["model_albedo+gain"]["own_rms_deg"] = clouds
    assert words in ep.verdict(res, "tilt0_fov90")[3]
    json.dumps(res)                                             # the results stay JSON-able
