"""CCSDS attitude ephemerides (AEM) in: every declared convention gives the same attitude, checked against the
standard's own direction-cosine matrix of the quaternion; gaps, useable spans, malformed messages; the export's
AEM reads back to the run's attitude."""
import numpy as np
import pytest

from simcore.environment import ccsds
from simcore.environment.epochs import Epochs
from simcore.environment.telemetry import read_attitude_history
from simcore.errors import InvalidInputError

START = "2020-11-15T00:00:00Z"


def ccsds_dcm(q1, q2, q3, qc):
    """The CCSDS ADM (504.0-B-1, annex on quaternions) matrix of an A2B quaternion: v_B = M v_A, written out
    element by element as the standard prints it; the oracle of these tests."""
    return np.array([
        [q1 * q1 - q2 * q2 - q3 * q3 + qc * qc, 2 * (q1 * q2 + q3 * qc), 2 * (q1 * q3 - q2 * qc)],
        [2 * (q1 * q2 - q3 * qc), -q1 * q1 + q2 * q2 - q3 * q3 + qc * qc, 2 * (q2 * q3 + q1 * qc)],
        [2 * (q1 * q3 + q2 * qc), 2 * (q2 * q3 - q1 * qc), -q1 * q1 - q2 * q2 + q3 * q3 + qc * qc],
    ])


def _aem(path, rows, *, frame_a="GCRF", frame_b="SC_BODY_1", direction="A2B", qtype="FIRST", atype="QUATERNION",
         start=START, step=10.0, version="2.0", drop=(), extra=(), segments=None):
    """Write an AEM of quaternion ``rows`` (N, 4) already in the declared order; ``segments``: a list of
    (offset_s, rows) to write several."""
    lines = [f"CCSDS_AEM_VERS = {version}", "CREATION_DATE = 2026-11-27T00:00:00", "ORIGINATOR = test", ""]
    for offset, part in segments or [(0.0, rows)]:
        ep = Epochs.from_any(start) + offset + step * np.arange(len(part))
        text = ccsds.format_epochs(ep)
        meta = {"OBJECT_NAME": "SAT", "OBJECT_ID": "2026-001A", "CENTER_NAME": "EARTH", "REF_FRAME_A": frame_a,
                "REF_FRAME_B": frame_b, "ATTITUDE_DIR": direction, "TIME_SYSTEM": "UTC", "START_TIME": text[0],
                "STOP_TIME": text[-1], "ATTITUDE_TYPE": atype, "QUATERNION_TYPE": qtype}
        lines += ["META_START"] + [f"{k} = {v}" for k, v in meta.items() if k not in drop] + list(extra)
        lines += ["META_STOP", "", "DATA_START"]
        lines += [t + " " + " ".join(f"{x:.17g}" for x in row) for t, row in zip(text, part)] + ["DATA_STOP", ""]
    path.write_text("\n".join(lines) + "\n")
    return path


def _random_unit(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _conj(e_c):
    return np.column_stack([-e_c[:, :3], e_c[:, 3]])


@pytest.fixture
def truth():
    """Slowly turning attitudes: (q1, q2, q3, qc) of the A2B quaternion from GCRF (A) to the body (B)."""
    rng = np.random.default_rng(34)
    base = _random_unit(rng, 1)[0]
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    angle = np.radians(0.5) * np.arange(12)                  # 0.5 deg per 10 s step: nothing flagged
    turn = np.column_stack([np.sin(angle / 2)[:, None] * axis, np.cos(angle / 2)])
    # compose as direction-cosine matrices (the oracle's own algebra): M = M(turn) M(base)
    mats = [ccsds_dcm(*t) @ ccsds_dcm(*base) for t in turn]
    return np.array(mats)


def _q_of(M):
    """An A2B quaternion (q1, q2, q3, qc) of the matrix M (v_B = M v_A), by the standard's formula inverted."""
    qc = 0.5 * np.sqrt(1.0 + np.trace(M))
    return np.array([M[1, 2] - M[2, 1], M[2, 0] - M[0, 2], M[0, 1] - M[1, 0], 4 * qc * qc]) / (4 * qc)


CONVENTIONS = [
    # (frame_a, frame_b, direction, qtype, rows of the truth's q = (q1, q2, q3, qc) in the declared convention)
    ("GCRF", "SC_BODY_1", "A2B", "FIRST", lambda q: q[:, [3, 0, 1, 2]]),
    ("GCRF", "SC_BODY_1", "A2B", "LAST", lambda q: q),
    ("GCRF", "SC_BODY_1", "B2A", "FIRST", lambda q: _conj(q)[:, [3, 0, 1, 2]]),
    ("GCRF", "SC_BODY_1", "B2A", "LAST", lambda q: _conj(q)),
    ("SC_BODY_1", "GCRF", "A2B", "LAST", lambda q: _conj(q)),          # A the body: A2B is body -> inertial
    ("SC_BODY_1", "GCRF", "B2A", "FIRST", lambda q: q[:, [3, 0, 1, 2]]),
]


@pytest.mark.parametrize("frame_a, frame_b, direction, qtype, order", CONVENTIONS)
def test_every_declared_convention_gives_the_attitude_of_the_standards_matrix(tmp_path, truth, frame_a,
                                                                             frame_b, direction, qtype, order):
    q = np.array([_q_of(M) for M in truth])
    path = _aem(tmp_path / "a.aem", order(q), frame_a=frame_a, frame_b=frame_b, direction=direction, qtype=qtype)
    hist = read_attitude_history(path)
    ep = Epochs.from_any(START) + 10.0 * np.arange(len(q))
    att = hist.attitude_at(ep)
    # the truth: v_body = M v_gcrf, so body vectors reach GCRF through M^T
    for axis in np.eye(3):
        np.testing.assert_allclose(att.to_gcrs(axis), np.einsum("nji,j->ni", truth, axis), atol=1e-12)


def test_a_known_rotation_reads_as_it_should(tmp_path):
    # the body turned +90 deg about the inertial z: body x points along GCRF +y; its A2B quaternion (GCRF -> body,
    # the standard's passive matrix) is e = sin 45 deg z, qc = cos 45 deg
    s = np.sqrt(0.5)
    path = _aem(tmp_path / "z.aem", np.array([[s, 0, 0, s]] * 3), qtype="FIRST")
    att = ccsds.read_aem(path).attitude_at(Epochs.from_any(START) + 5.0)
    np.testing.assert_allclose(att.to_gcrs([1.0, 0, 0])[0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(att.to_gcrs([0, 1.0, 0])[0], [-1, 0, 0], atol=1e-15)


def test_eme2000_attitudes_reach_gcrs_through_the_frame_bias(tmp_path):
    from simcore.environment import frames
    s = np.sqrt(0.5)
    path = _aem(tmp_path / "e.aem", np.array([[s, 0, 0, s]] * 3), frame_a="EME2000")
    ep = Epochs.from_any(START) + 5.0
    got = ccsds.read_aem(path).attitude_at(ep).to_gcrs([1.0, 0, 0])[0]
    B = frames.R_eme2000_from_gcrs(ep)[0]
    np.testing.assert_allclose(got, B.T @ [0, 1, 0], atol=1e-15)
    assert np.linalg.norm(got - [0, 1, 0]) > 5e-8                     # the bias (~0.1 urad) is really applied


def test_xml_aem_and_version_1(tmp_path, truth):
    q = np.array([_q_of(M) for M in truth])
    ep = ccsds.format_epochs(Epochs.from_any(START) + 10.0 * np.arange(len(q)))
    xml = ['<?xml version="1.0" encoding="UTF-8"?>', '<aem id="CCSDS_AEM_VERS" version="1.0">',
           "<header><CREATION_DATE>2026-11-27T00:00:00</CREATION_DATE><ORIGINATOR>t</ORIGINATOR></header>",
           "<body><segment><metadata><OBJECT_NAME>S</OBJECT_NAME><OBJECT_ID>2026-001A</OBJECT_ID>",
           "<REF_FRAME_A>GCRF</REF_FRAME_A><REF_FRAME_B>SC_BODY_1</REF_FRAME_B><ATTITUDE_DIR>A2B</ATTITUDE_DIR>",
           f"<TIME_SYSTEM>UTC</TIME_SYSTEM><START_TIME>{ep[0]}</START_TIME><STOP_TIME>{ep[-1]}</STOP_TIME>",
           "<ATTITUDE_TYPE>QUATERNION</ATTITUDE_TYPE><QUATERNION_TYPE>LAST</QUATERNION_TYPE></metadata><data>"]
    for t, row in zip(ep, q):
        parts = "".join(f"<{n}>{float(x)!r}</{n}>" for n, x in zip(("Q1", "Q2", "Q3", "QC"), row))
        xml.append(f"<attitudeState><quaternionState><EPOCH>{t}</EPOCH><quaternion>{parts}</quaternion>"
                   "</quaternionState></attitudeState>")
    xml.append("</data></segment></body></aem>")
    (tmp_path / "a.xml").write_text("\n".join(xml))
    kvn = ccsds.read_aem(_aem(tmp_path / "a.aem", q, qtype="LAST"))
    got = read_attitude_history(tmp_path / "a.xml")
    np.testing.assert_array_equal(got.q_frame_from_body, kvn.q_frame_from_body)


def test_segments_gaps_and_useable_spans(tmp_path):
    s = np.sqrt(0.5)
    rows = np.array([[1.0, 0, 0, 0]] * 4)
    # two segments 60 s apart (a gap over HistoryLimits' 30 s), the second starting where a third would join
    path = _aem(tmp_path / "g.aem", None, segments=[(0.0, rows), (90.0, rows), (120.0, np.array([[s, 0, 0, s]] * 3))])
    h = ccsds.read_aem(path)
    assert len(h) == 4 + 4 + 3 - 1 and h.dropped["segment_boundary_duplicates"] == 1
    f = h.flags()
    assert f["counts"]["gap"] == 1
    assert not h.trusted(Epochs.from_any(START) + 60.0)[0]
    with pytest.raises(InvalidInputError, match="gap, a jump or frozen"):
        h.attitude_at(Epochs.from_any(START) + np.array([10.0, 60.0]))
    extra = (f"USEABLE_START_TIME = {ccsds.format_epochs(Epochs.from_any(START) + 10.0)[0]}",)
    h2 = ccsds.read_aem(_aem(tmp_path / "u.aem", rows, extra=extra))
    assert len(h2) == 3 and h2.dropped["outside_useable_span"] == 1


@pytest.mark.parametrize("change, match", [
    (dict(drop=("QUATERNION_TYPE",)), "QUATERNION_TYPE = (missing): declare FIRST or LAST"),
    (dict(drop=("ATTITUDE_DIR",)), "ATTITUDE_DIR = (missing): declare A2B or B2A"),
    (dict(drop=("REF_FRAME_B",)), "lacks REF_FRAME_B"),
    (dict(atype="EULER_ANGLE"), "ATTITUDE_TYPE = EULER_ANGLE: sunsim reads quaternion AEMs"),
    (dict(frame_a="MOON_ME"), "unknown reference frame 'MOON_ME'"),
    (dict(frame_a="SC_BODY_2"), "needs one spacecraft body frame"),
    (dict(version="7.0"), "CCSDS_AEM_VERS = 7.0"),
])
def test_malformed_aems_get_one_clear_line(tmp_path, change, match):
    path = _aem(tmp_path / "bad.aem", np.array([[1.0, 0, 0, 0]] * 3), **change)
    with pytest.raises(InvalidInputError, match=match.replace("(", r"\(").replace(")", r"\)")) as e:
        read_attitude_history(path)
    assert "\n" not in str(e.value)


def test_non_unit_and_unordered_quaternions_get_one_clear_line(tmp_path):
    rows = np.array([[1.0, 0, 0, 0]] * 3)
    rows[1] = [0.9, 0.0, 0.0, 0.0]
    with pytest.raises(InvalidInputError,
                       match=r"bad.aem:\d+: the quaternion at 2020-11-15T00:00:10.000Z has norm 0.9"):
        ccsds.read_aem(_aem(tmp_path / "bad.aem", rows))
    path = _aem(tmp_path / "order.aem", np.array([[1.0, 0, 0, 0]] * 3))
    lines = path.read_text().splitlines()
    i = lines.index("DATA_START") + 2
    lines[i], lines[i + 1] = lines[i + 1], lines[i]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InvalidInputError, match="does not come after"):
        ccsds.read_aem(path)
    with pytest.raises(InvalidInputError, match="declares its frame and direction"):
        read_attitude_history(_aem(tmp_path / "ok.aem", np.array([[1.0, 0, 0, 0]] * 3)), frame="TEME")


def test_written_aem_reads_back_to_the_same_attitude(tmp_path):
    rng = np.random.default_rng(7)
    q = _random_unit(rng, 30)
    q[:, 0] = np.abs(q[:, 0]) + 3.0                                  # near one another: a smooth-ish history
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    ep = Epochs.from_any(START) + 2.0 * np.arange(30)
    for direction in ("body_to_frame", "frame_to_body"):
        ccsds.write_aem(tmp_path / "w.aem", ep, q, frame="GCRF", direction=direction)
        h = ccsds.read_aem(tmp_path / "w.aem")
        want = q if direction == "body_to_frame" else q * [1, -1, -1, -1]
        sign = np.sign(np.sum(h.q_frame_from_body * want, axis=1))[:, None]
        np.testing.assert_allclose(h.q_frame_from_body * sign, want, atol=1e-15)


def test_a_run_plan_takes_the_aem_samples_and_the_oem_orbit(tmp_path):
    # `sunsim run --attitude FILE.aem --orbit FILE.oem` with neither --start nor --duration: the run's epochs are the
    # AEM's trusted samples, its attitude the AEM's, its orbit the OEM's (schedule.plan, no rendering here)
    from simcore.environment.ephemeris import write_orbit_oem
    from simcore.environment.orbit import Orbit
    from simcore.pipeline.options import RunOptions
    from simcore.pipeline.schedule import plan
    start = "2016-07-02T00:30:00Z"
    oem = tmp_path / "o.oem"
    write_orbit_oem(oem, Orbit.default(), Epochs.range("2016-07-02T00:25:00Z", 900, 60.0))
    s = np.sqrt(0.5)
    aem = _aem(tmp_path / "a.aem", np.array([[s, 0, 0, s]] * 5), start=start, step=10.0, frame_a="EME2000")
    p = plan(RunOptions(attitude_file=str(aem), orbit_file=str(oem)))
    assert p.source == "attitude samples" and len(p.epochs) == 5
    np.testing.assert_allclose(p.epochs.seconds_since(start), 10.0 * np.arange(5), atol=1e-6)
    np.testing.assert_allclose(p.attitude.to_gcrs([1.0, 0, 0]), np.tile([0, 1, 0], (5, 1)), atol=1e-6)
    late = _aem(tmp_path / "late.aem", np.array([[s, 0, 0, s]] * 5), start="2016-07-02T00:39:30Z", step=10.0)
    with pytest.raises(InvalidInputError, match="covers 2016-07-02T00:25:00.000Z .. 2016-07-02T00:39:00.000Z"):
        plan(RunOptions(attitude_file=str(late), orbit_file=str(oem)))
