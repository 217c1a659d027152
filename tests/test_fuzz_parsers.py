"""Fuzzing of every file reader with mutated excerpts of the real files in ``shared/data``.

Each case takes a short excerpt of a real file (the header and the first few records or
epochs: small enough that a case costs milliseconds, large enough that every kind of line is
there; the shared data hold no SEM file and their RINEX 3 observation files are CRINEX, so
the RINEX 2 observation excerpt is also written as RINEX 3 and the YUMA excerpt as SEM),
applies one to three mutations drawn by hypothesis (truncation at a byte, a bit flipped, a line
deleted or duplicated, a field replaced by garbage: a letter, ``nan``, ``inf``, an overflow, a
sign, a blank) and reads the result.
Every case must either give a complete, valid result (every number finite, elements physical,
no duplicate satellite or transmitter) or raise the reader's own error (a ``ValueError``
subclass) whose message names the file and a line; any other exception fails the test, and so
does a result holding a NaN.

Cases per reader: ``OARAIM_FUZZ_EXAMPLES`` (default 500) for the readers through georinex or
pandas, twice that for the pure-Python ones (docs/errors.md gives the counts and times
measured on 2 cores). Derandomized: the same cases on every run.
"""

import gzip
import itertools
import os
import re
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from oaraim import geometry, readers, sim
from oaraim.readers import navigation, recording, rinex_obs
from oaraim.studies import availability_map
from tests.test_almanac import _sem_text

#: cases for the readers that go through georinex or pandas (a few ms each); the others,
#: which parse in pure Python in well under a millisecond, run twice as many
EXAMPLES = int(os.environ.get("OARAIM_FUZZ_EXAMPLES", "500"))


def fuzz(factor=1):
    return settings(max_examples=factor * EXAMPLES, deadline=None, derandomize=True,
                    database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow, HealthCheck.data_too_large])


#: a numeric warning (an invalid cast, an overflow) inside a reader is a failure too
pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")
#: "line 12" or a recording's "row 3 (file line 5)"
LINE = re.compile(r"\bline \d+")

#: what a garbled field becomes
GARBAGE = ["", "x", "nan", "NaN", "inf", "-inf", "1e999", "1D+999", "-1", "-0.5", "1.5", "0",
           "9999999999999", "--", ".", "D", ",", "\t", "é", "\x00", "G99", "  "]

MUTATION = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0, 1)),
    st.tuples(st.just("flip"), st.floats(0, 1), st.integers(0, 7)),
    st.tuples(st.just("delete"), st.floats(0, 1)),
    st.tuples(st.just("duplicate"), st.floats(0, 1)),
    st.tuples(st.just("garble"), st.floats(0, 1), st.integers(0, 20), st.sampled_from(GARBAGE),
              st.booleans()),
)
MUTATIONS = st.lists(MUTATION, min_size=1, max_size=3)


def mutate(data: bytes, mutations) -> bytes:
    """Apply the mutations in turn (positions are fractions of the current length)."""
    for m in mutations:
        kind, where = m[0], m[1]
        lines = data.split(b"\n")
        if kind == "truncate":
            data = data[:int(where * len(data))]
        elif kind == "flip" and data:
            i = min(int(where * len(data)), len(data) - 1)
            data = data[:i] + bytes([data[i] ^ (1 << m[2])]) + data[i + 1:]
        elif kind == "delete" and len(lines) > 1:
            del lines[min(int(where * len(lines)), len(lines) - 1)]
            data = b"\n".join(lines)
        elif kind == "duplicate":
            i = min(int(where * len(lines)), len(lines) - 1)
            lines.insert(i, lines[i])
            data = b"\n".join(lines)
        elif kind == "garble":
            i = min(int(where * len(lines)), len(lines) - 1)
            line = lines[i].decode("latin-1")
            tokens = list(re.finditer(r"[^\s,:]+", line))
            if tokens:
                t = tokens[m[2] % len(tokens)]
                new = m[3].rjust(len(t.group())) if m[4] else m[3]
                line = line[:t.start()] + new + line[t.end():]
                lines[i] = line.encode("utf-8")
                data = b"\n".join(lines)
    return data


class Cases:
    """Mutated files written under one folder, each under a new name (the readers cache parses
    by path, size and mtime: a new name can never hit a stale entry)."""

    def __init__(self, folder):
        self.folder = folder
        self.count = itertools.count()
        self.outcomes = {}

    def write(self, data: bytes, suffix: str):
        p = self.folder / f"case{next(self.count):06d}{suffix}"
        p.write_bytes(data)
        return p

    def note(self, reader, outcome):
        self.outcomes.setdefault(reader, {}).setdefault(outcome, 0)
        self.outcomes[reader][outcome] += 1


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    c = Cases(tmp_path_factory.mktemp("fuzz"))
    yield c
    print(f"\nfuzz outcomes per reader (ok / error): {c.outcomes}")


def expect_parse_error(error_type, path, call):
    """Run ``call``; its result, or None after the reader's own error naming file and line."""
    try:
        return call()
    except error_type as e:
        msg = str(e)
        assert path.name in msg, msg
        assert LINE.search(msg), f"no line number in: {msg}"
        return None


def all_finite(*arrays):
    for a in arrays:
        a = np.asarray(a)
        if a.dtype.kind in "fc":
            assert np.all(np.isfinite(a)), a


# --------------------------------------------------------------------------- excerpts


def _lines(path):
    opener = gzip.open if str(path).endswith(".gz") else open
    with opener(path, "rb") as f:
        return f.read().split(b"\n")


def _header_end(lines):
    return next(k for k, s in enumerate(lines) if b"END OF HEADER" in s)


@pytest.fixture(scope="module")
def rinex2_nav(shared_data):
    """brdc1820.10n: the header and the first three records (8 lines each)."""
    lines = _lines(shared_data / "nav" / "brdc1820.10n")
    end = _header_end(lines)
    return b"\n".join(lines[:end + 1 + 24]) + b"\n"


@pytest.fixture(scope="module")
def rinex3_nav(shared_data):
    """ELKO...MN.rnx.gz decompressed: the header, two GPS records and one Galileo record."""
    lines = _lines(shared_data / "nav" / "ELKO00USA_R_20182100000_01D_MN.rnx.gz")
    end = _header_end(lines)
    starts = [k for k in range(end + 1, len(lines)) if lines[k][:1] in (b"G", b"E")
              and lines[k][1:3].strip().isdigit()]
    gps = [k for k in starts if lines[k][:1] == b"G"][:2]
    gal = [k for k in starts if lines[k][:1] == b"E"][:1]
    body = [line for k in gps + gal for line in lines[k:k + 8]]
    return b"\n".join(lines[:end + 1] + body) + b"\n"


@pytest.fixture(scope="module")
def rinex_obs_excerpt(shared_data):
    """07590920.05o: the header and the first three epochs (8 satellites, one line each)."""
    lines = _lines(shared_data / "obs" / "07590920.05o")
    end = _header_end(lines)
    return b"\n".join(lines[:end + 1 + 27]) + b"\n"


@pytest.fixture(scope="module")
def rinex3_obs_excerpt(rinex_obs_excerpt):
    """The same three epochs written as RINEX 3.03 (the shared data hold no RINEX 3 observation
    file): observables L1C C1C L2W C2W, epoch lines '> YYYY MM DD hh mm ss', one line per
    satellite starting with its id."""
    lines = rinex_obs_excerpt.decode().split("\n")
    end = next(k for k, s in enumerate(lines) if "END OF HEADER" in s)
    head = ["     3.03           OBSERVATION DATA    G                   RINEX VERSION / TYPE"]
    for s in lines[1:end + 1]:
        label = s[60:80].strip()
        if label == "# / TYPES OF OBSERV":
            s = f"{'G    4 L1C C1C L2W C2W':60s}SYS / # / OBS TYPES"
        elif label in ("WAVELENGTH FACT L1/2", "RINEX VERSION / TYPE"):
            continue
        head.append(s)
    body, k = [], end + 1
    while k < len(lines) and lines[k].strip():
        e = lines[k]
        n = int(e[29:32])
        sats = [e[32 + 3 * i:35 + 3 * i].replace(" ", "0") for i in range(n)]
        body.append(f"> 20{e[1:3]} {int(e[4:6]):02d} {int(e[7:9]):02d} {int(e[10:12]):02d} "
                    f"{int(e[13:15]):02d}{e[15:26]}  {e[28]}{n:3d}")
        body += [sat + lines[k + 1 + i] for i, sat in enumerate(sats)]
        k += 1 + n
    return ("\n".join(head + body) + "\n").encode()


@pytest.fixture(scope="module")
def yuma_excerpt(shared_data):
    """almyuma_01jan2020.txt: the first three satellite blocks."""
    text = (shared_data / "almanac" / "almyuma_01jan2020.txt").read_bytes()
    return b"\r\n\r\n".join(text.split(b"\r\n\r\n")[:3]) + b"\r\n"


@pytest.fixture(scope="module")
def sem_excerpt(yuma_excerpt, tmp_path_factory):
    """The YUMA excerpt written as a SEM file (the shared data hold no SEM file)."""
    p = tmp_path_factory.mktemp("sem") / "excerpt.txt"
    p.write_bytes(yuma_excerpt)
    return (_sem_text(geometry.read_yuma(p)) + "\n").encode()


TOWERS = (b"lat_deg,lon_deg,height_m,carrier\n"
          b"33.9806,-117.3755,30,carrier_a\n"
          b"33.9850,-117.3700,25.5,carrier_b\n"
          b"33.9750,-117.3800,40,carrier_a\n")


@pytest.fixture(scope="module")
def recording_folder(tmp_path_factory):
    """The example drive written as CSV tables (half a second: a few rows per table)."""
    folder = tmp_path_factory.mktemp("recording")
    rec = sim.example_recording(duration_s=0.5, imu_rate_hz=10.0, pr_rate_hz=4.0)
    recording.write_recording(folder / "drive", rec, format="csv")
    return folder / "drive"


# --------------------------------------------------------------------------- readers


def _check_ephemeris(eph):
    assert eph.prns.size > 0 and len(set(eph.prns)) == eph.prns.size
    all_finite(*eph._params.values())
    for k in range(eph.prns.size):
        n = int(eph.n_records[k])
        p = {name: eph._params[name][k] for name in ("e", "sqrt_a")}
        ok = np.isfinite(eph._toe_healthy[k])
        assert np.all((p["e"][ok] >= 0) & (p["e"][ok] <= navigation.E_MAX)), p
        assert np.all(p["sqrt_a"][ok] > 0), p
        assert n >= 1


def _nav_case(cases, data, suffix):
    path = cases.write(data, suffix)

    def call():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return geometry.load_navigation(path, systems=("G", "E"))

    eph = expect_parse_error(navigation.NavigationFileError, path, call)
    if eph is not None:
        _check_ephemeris(eph)
    return eph


@fuzz()
@given(mutations=MUTATIONS)
def test_fuzz_rinex2_navigation(cases, rinex2_nav, mutations):
    eph = _nav_case(cases, mutate(rinex2_nav, mutations), ".10n")
    cases.note("rinex2 nav", "ok" if eph is not None else "error")


@fuzz()
@given(mutations=MUTATIONS)
def test_fuzz_rinex3_navigation(cases, rinex3_nav, mutations):
    eph = _nav_case(cases, mutate(rinex3_nav, mutations), ".rnx")
    cases.note("rinex3 nav", "ok" if eph is not None else "error")


def _check_observations(obs):
    t, pr, ok = obs.t_gps_s, obs.pseudorange_m, obs.valid
    assert t.size > 0 and pr.shape == ok.shape == (t.size, obs.sv.size)
    all_finite(t, pr)
    assert np.all(np.diff(t) > 0)
    assert len(set(obs.sv)) == obs.sv.size
    lo, hi = rinex_obs.PSEUDORANGE_SPAN_M
    assert np.all((pr[ok] > lo) & (pr[ok] < hi)) and np.all(pr[~ok] == 0)


@fuzz(2)
@given(mutations=MUTATIONS)
def test_fuzz_rinex_observations(cases, rinex_obs_excerpt, mutations):
    """Strict and lenient reading of a mutated observation file: the strict reader gives the
    whole file or an error naming the line; the lenient one gives the good epochs and a warning
    naming the line for each skipped one (or the same error where nothing is left)."""
    path = cases.write(mutate(rinex_obs_excerpt, mutations), ".05o")
    strict = expect_parse_error(rinex_obs.ObservationFileError, path,
                                lambda: rinex_obs.read_observations(path))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lenient = expect_parse_error(rinex_obs.ObservationFileError, path,
                                     lambda: rinex_obs.read_observations(path, lenient=True))
    skipped = [str(w.message) for w in caught if w.category is rinex_obs.ObservationFileWarning]
    for msg in skipped:
        assert path.name in msg and LINE.search(msg), msg
    if strict is not None:
        _check_observations(strict)
        assert lenient is not None and not skipped
        np.testing.assert_array_equal(lenient.pseudorange_m, strict.pseudorange_m)
    if lenient is not None:
        _check_observations(lenient)
        assert list(lenient.skipped) == skipped
    cases.note("rinex obs", "ok" if strict is not None else
               "error" if lenient is None else "error, lenient skipped")


@fuzz(2)
@given(mutations=MUTATIONS)
def test_fuzz_rinex3_observations(cases, rinex3_obs_excerpt, mutations):
    """The RINEX 3 epoch format: the same strict / lenient contract."""
    assert rinex_obs.read_observations(cases.write(rinex3_obs_excerpt, ".rnx")).t_gps_s.size == 3
    path = cases.write(mutate(rinex3_obs_excerpt, mutations), ".rnx")
    strict = expect_parse_error(rinex_obs.ObservationFileError, path,
                                lambda: rinex_obs.read_observations(path))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lenient = expect_parse_error(rinex_obs.ObservationFileError, path,
                                     lambda: rinex_obs.read_observations(path, lenient=True))
    for w in caught:
        if w.category is rinex_obs.ObservationFileWarning:
            assert path.name in str(w.message) and LINE.search(str(w.message)), w.message
    for obs in (strict, lenient):
        if obs is not None:
            _check_observations(obs)
    cases.note("rinex3 obs", "ok" if strict is not None else
               "error" if lenient is None else "error, lenient skipped")


@pytest.fixture(scope="module")
def crinex_excerpt(shared_data):
    """TLSE...crx.gz decompressed from gzip (CRINEX 3 text): the header without TIME OF LAST
    OBS and the first three epochs (an epoch line, a clock line and one line per satellite)."""
    import hatanaka

    lines = _lines(shared_data / "obs3" / "TLSE00FRA_R_20240011800_01H_30S_MO.crx.gz")
    end = _header_end(lines)
    decoded = hatanaka.crx2rnx(b"\n".join(lines)).split(b"\n")
    counts = [int(s[32:35]) for s in decoded if s[:1] == b">"][:3]  # satellites per epoch
    k = end + 1 + sum(2 + n for n in counts)  # CRINEX: epoch line, clock line, satellites
    head = [s for s in lines[:end + 1] if b"TIME OF LAST OBS" not in s]
    return b"\n".join(head + lines[end + 1:k]) + b"\n"


@fuzz()
@given(mutations=MUTATIONS)
def test_fuzz_crinex_observations(cases, crinex_excerpt, mutations):
    """A mutated CRINEX file: the Hatanaka decoder stops (the error names the CRINEX line), or
    the decoded text is read strictly (an error names the line of the decompressed text), or
    a whole table comes back (a garbled digit of a compressed difference decodes to numbers)."""
    assert rinex_obs.read_observation_table(cases.write(crinex_excerpt, ".crx")).t_gps_s.size == 3
    path = cases.write(mutate(crinex_excerpt, mutations), ".crx")
    table = expect_parse_error(rinex_obs.ObservationFileError, path,
                               lambda: rinex_obs.read_observation_table(path))
    if table is not None:
        assert table.t_gps_s.size > 0 and np.all(np.diff(table.t_gps_s) > 0)
        assert len(set(table.sv)) == table.sv.size
        for a in table.values.values():
            assert a.shape == (table.t_gps_s.size, table.sv.size)
            assert not np.any(np.isinf(a))
    cases.note("crinex obs", "ok" if table is not None else "error")


def _check_almanac(alm):
    r = alm.records
    assert r.prn.size > 0 and len(set(r.prn.tolist())) == r.prn.size
    all_finite(*r)
    assert np.all((r.e >= 0) & (r.e < 1)) and np.all(r.sqrt_a > 0)


@fuzz(2)
@given(mutations=MUTATIONS)
def test_fuzz_yuma(cases, yuma_excerpt, mutations):
    path = cases.write(mutate(yuma_excerpt, mutations), ".alm")
    alm = expect_parse_error(readers.AlmanacFileError, path, lambda: geometry.read_yuma(path))
    if alm is not None:
        _check_almanac(alm)
    cases.note("yuma", "ok" if alm is not None else "error")


@fuzz(2)
@given(mutations=MUTATIONS)
def test_fuzz_sem(cases, sem_excerpt, mutations):
    path = cases.write(mutate(sem_excerpt, mutations), ".al3")
    alm = expect_parse_error(readers.AlmanacFileError, path, lambda: geometry.read_sem(path))
    if alm is not None:
        _check_almanac(alm)
    cases.note("sem", "ok" if alm is not None else "error")


@fuzz(2)
@given(mutations=MUTATIONS)
def test_fuzz_tower_csv(cases, mutations):
    path = cases.write(mutate(TOWERS, mutations), ".csv")
    towers = expect_parse_error(availability_map.TowerFileError, path,
                                lambda: availability_map.read_towers(path))
    if towers is not None:
        lat, lon, h, carrier, names = towers
        all_finite(lat, lon, h)
        rows = set(zip(lat, np.mod(lon, 360.0), h, carrier, strict=True))
        assert len(rows) == lat.size > 0 and len(names) > 0
    cases.note("tower csv", "ok" if towers is not None else "error")


@fuzz()
@given(table=st.sampled_from(["transmitters", "pseudoranges", "truth"]), mutations=MUTATIONS)
def test_fuzz_recording_csv(cases, recording_folder, table, mutations):
    """One table of a CSV recording mutated (a copy of the folder per case)."""
    folder = cases.folder / f"rec{next(cases.count):06d}"
    folder.mkdir()
    for f in recording_folder.iterdir():
        data = f.read_bytes()
        (folder / f.name).write_bytes(mutate(data, mutations) if f.name == f"{table}.csv"
                                      else data)

    def call():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", recording.RecordingWarning)
            return recording.load_recording(folder)

    try:
        rec = call()
    except recording.RecordingError as e:
        msg = str(e)
        assert str(folder) in msg, msg  # the mutated table or one it breaks (a lost tx_id)
        assert LINE.search(msg), f"no line number in: {msg}"
        rec = None
    if rec is not None:
        for name in recording.TABLES:
            df = rec.table(name)
            if df is not None:
                all_finite(*(df[c].to_numpy() for c in df.columns
                             if df[c].dtype.kind == "f"))
        assert rec.transmitters["tx_id"].is_unique
    cases.note(f"recording {table}", "ok" if rec is not None else "error")
