"""The one time representation: UTC two-part Julian dates, accepted from edge types."""
import datetime as dt

import erfa
import numpy as np
import pytest

from simcore.environment.epochs import Epochs


def test_iso_datetime_and_datetime64_agree():
    # 2016-07-02T00:00:00 UTC is JD 2457571.5 (Astronomical Almanac JD tables: JD 2457570.5 = 2016-07-01 0h).
    a = Epochs.from_any("2016-07-02T00:00:00Z")
    b = Epochs.from_any(dt.datetime(2016, 7, 2, tzinfo=dt.timezone.utc))
    c = Epochs.from_any(np.datetime64("2016-07-02T00:00:00"))
    d = Epochs.from_any(dt.datetime(2016, 7, 2, 2, 0, tzinfo=dt.timezone(dt.timedelta(hours=2))))
    assert a == b == c == d
    assert a.jd1[0] == 2457571.5 and a.jd2[0] == 0.0


def test_calendar_conversion_matches_erfa():
    # erfa.dtf2d is SOFA's calendar -> two-part JD for UTC (independent implementation).
    stamps = ["1999-12-31T23:59:59", "2000-06-30T18:50:19.733571", "2016-07-02T12:34:56.5", "2026-11-21T07:01:00"]
    ours = Epochs.from_any(stamps)
    for i, s in enumerate(stamps):
        t = dt.datetime.fromisoformat(s)
        sec = t.second + t.microsecond * 1e-6
        j1, j2 = erfa.dtf2d("UTC", t.year, t.month, t.day, t.hour, t.minute, sec)
        assert (ours.jd1[i] - j1) + (ours.jd2[i] - j2) == pytest.approx(0.0, abs=1e-11)


def test_range_and_seconds_since():
    e = Epochs.range("2016-07-02T00:00:00Z", duration_s=86400, step_s=1)
    assert len(e) == 86400
    s = e.seconds_since("2016-07-02T00:00:00Z")
    np.testing.assert_allclose(s, np.arange(86400.0), atol=1e-6)
    assert e.iso()[-1] == "2016-07-02T23:59:59.000Z"


def test_normalised_split_keeps_fraction_in_a_day():
    e = Epochs(2457571.0, 1.75)  # 2457572.75 = 2016-07-03T06:00
    assert e.jd1[0] == 2457572.5 and e.jd2[0] == pytest.approx(0.25)
    assert e.iso() == ["2016-07-03T06:00:00.000Z"]


def test_tt_minus_utc_in_2016_is_68_184_s():
    # TT - UTC = 32.184 s + (TAI - UTC = 36 s from 2015-07-01 to 2016-12-31; IERS Bulletin C).
    tt1, tt2 = Epochs.from_any("2016-07-02T00:00:00Z").tt()
    e = Epochs.from_any("2016-07-02T00:00:00Z")
    dt_s = ((tt1 - e.jd1) + (tt2 - e.jd2)) * 86400
    assert dt_s[0] == pytest.approx(68.184, abs=1e-6)


@pytest.mark.parametrize("bad, match", [
    ("2016-13-02T00:00:00Z", "month"),
    ("yesterday", "cannot read 'yesterday'"),
    (3.5, "cannot use float"),
])
def test_bad_times_say_what_to_give(bad, match):
    with pytest.raises((ValueError, TypeError), match=match):
        Epochs.from_any(bad)


def test_bad_range():
    with pytest.raises(ValueError, match="step must be a positive"):
        Epochs.range("2016-07-02", 10, 0)
    with pytest.raises(ValueError, match="duration must be a positive"):
        Epochs.range("2016-07-02", -5, 1)


def test_leap_second_day_maps_to_erfa_utc():
    # 2016-12-31 ended with a leap second (IERS Bulletin C 52): 23:59:59 UTC that day is
    # TAI 2017-01-01T00:00:35 (TAI - UTC = 36 s until the leap, 37 s after).
    e = Epochs.from_any("2016-12-31T23:59:59Z")
    t1, t2 = e.tai()
    j1, j2 = erfa.dtf2d("TAI", 2017, 1, 1, 0, 0, 35.0)
    assert ((t1 - j1) + (t2 - j2))[0] * 86400 == pytest.approx(0.0, abs=1e-6)


def test_far_future_dates_do_not_warn():
    # erfa warns "dubious year" past its leap-second table; the suite turns warnings into errors.
    tt1, tt2 = Epochs.from_any("2040-01-01T00:00:00Z").tt()
    assert np.isfinite(tt1 + tt2).all()


# ---- leap seconds (issue 33 item 7) -------------------------------------------------------------
# 2016-12-31 and 2015-06-30 ended in a leap second (IERS Bulletin C 52 and 49); 2016-07-02 did not.
@pytest.mark.parametrize("day, next_day", [("2016-12-31", "2017-01-01"), ("2015-06-30", "2015-07-01")])
def test_leap_second_lies_between_its_neighbours(day, next_day):
    before, leap, after = Epochs.from_any([f"{day}T23:59:59Z", f"{day}T23:59:60Z", f"{next_day}T00:00:00Z"])
    assert leap.seconds_since(before)[0] == pytest.approx(1.0, abs=1e-6)
    assert after.seconds_since(leap)[0] == pytest.approx(1.0, abs=1e-6)
    # the same in TAI, SOFA's own reading of the leap second (independent of our arithmetic)
    tai = [e.tai() for e in (before, leap, after)]
    gaps = [((tai[i + 1][0] - tai[i][0]) + (tai[i + 1][1] - tai[i][1]))[0] * 86400 for i in range(2)]
    assert gaps == [pytest.approx(1.0, abs=1e-6)] * 2
    assert leap.iso() == [f"{day}T23:59:60.000Z"]
    assert (before + 1.0).iso() == [f"{day}T23:59:60.000Z"] and (leap + 1.0).iso() == [f"{next_day}T00:00:00.000Z"]


def test_leap_second_matches_erfa_and_keeps_offsets():
    j1, j2 = erfa.dtf2d("UTC", 2016, 12, 31, 23, 59, 60.5)
    e = Epochs.from_any("2016-12-31T23:59:60.5Z")
    assert (e.jd1[0] - j1) + (e.jd2[0] - j2) == pytest.approx(0.0, abs=1e-11)
    assert Epochs.from_any("2017-01-01T00:59:60.5+01:00") == e


def test_range_across_a_leap_second_counts_si_seconds():
    e = Epochs.range("2016-12-31T23:59:58Z", duration_s=4, step_s=1)
    assert e.iso() == ["2016-12-31T23:59:58.000Z", "2016-12-31T23:59:59.000Z", "2016-12-31T23:59:60.000Z",
                       "2017-01-01T00:00:00.000Z"]
    np.testing.assert_allclose(e.seconds_since(e[0]), [0.0, 1.0, 2.0, 3.0], atol=1e-6)


@pytest.mark.parametrize("bad, match", [
    ("2016-07-02T23:59:60Z", "2016-07-02 has no leap second"),
    ("2016-12-31T12:00:60Z", "only as 23:59:60"),
])
def test_second_60_refused_where_there_is_no_leap_second(bad, match):
    from simcore.errors import InvalidInputError
    with pytest.raises(InvalidInputError, match=match):
        Epochs.from_any(bad)
