"""The real GNSS files: a registry of every file with its checksum and public origin, and where
a run finds them.

Resolution, first match wins:

1. ``OARAIM_DATA`` set to a folder: files are read from it directly (nothing is downloaded).
2. ``OARAIM_DATA`` set to an ``http(s)://`` or ``file://`` URL: a mirror with the same layout
   (``nav/``, ``obs/``, ``almanac/``, ``orbits/``); files are fetched into the cache and their
   sha256 checked against the registry.
3. ``OARAIM_DATA`` unset: ``../shared/data`` beside the source checkout when it holds the file,
   else the cache, filled from each file's public origin (checksum checked).

The cache is ``OARAIM_CACHE`` if set, else the user cache folder (``pooch.os_cache("oaraim")``).
The registry is data (``data_registry.json`` beside this module), not code.

Every failure raises ``DataUnavailable`` (a ``ValueError``, so the CLI exits 2 without a
traceback) with one line: which file, why, and the command or setting that fixes it.
"""

import hashlib
import json
import os
import re
import shutil
import sys
import tempfile
import urllib.parse
import urllib.request
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

#: the source checkout (where ``oaraim/`` sits); ``../shared/data`` beside it is CI's data folder
REPO_ROOT = Path(__file__).resolve().parent.parent
REGISTRY_FILE = Path(__file__).with_name("data_registry.json")
#: seconds before a silent server counts as down
TIMEOUT_S = 60


class DataUnavailable(ValueError):
    """A real data file could not be found or fetched; the message is one line with the fix."""


class SourceUnreachable(DataUnavailable):
    """The download itself failed (refused, timed out, HTTP error): the source, not the file,
    is the problem, so other files from the same source would fail the same way."""


@dataclass(frozen=True)
class DataFile:
    """One entry of the registry (``data_registry.json``): a real file, how to check it and
    where it comes from."""

    name: str
    """Path under the data folder (``OARAIM_DATA``, a mirror, or the cache), e.g.
    ``"nav/brdc0010.22n"``."""
    sha256: str
    """Hex sha256 of the file itself, checked whenever it is fetched or first read."""
    size: int
    """Size of the file in bytes."""
    url: str
    """Its public HTTPS origin, fetched when no local copy or mirror holds it."""
    licence: str
    """The licence or notice under which the origin publishes it."""
    description: str
    """One line on what the file is (format, day, station)."""


@lru_cache(maxsize=1)
def registry() -> dict:
    """{name: DataFile} for every known file, from ``data_registry.json``."""
    raw = json.loads(REGISTRY_FILE.read_text())["files"]
    return {n: DataFile(name=n, **v) for n, v in raw.items()}


def entry(name: str) -> DataFile:
    """The registry entry of ``name``; an unknown name lists the valid ones."""
    reg = registry()
    if name not in reg:
        raise DataUnavailable(f"unknown data file {name!r}; known files: {', '.join(reg)}")
    return reg[name]


def cache_dir() -> Path:
    """Where fetched files are kept: ``OARAIM_CACHE``, else the user cache folder."""
    env = os.environ.get("OARAIM_CACHE")
    if env:
        return Path(env).expanduser()
    import pooch

    return Path(pooch.os_cache("oaraim"))


def _is_url(s: str) -> bool:
    return s.startswith(("http://", "https://", "file://"))


def _env_data() -> str | None:
    env = os.environ.get("OARAIM_DATA", "").strip()
    if env and not _is_url(env) and not Path(env).expanduser().is_dir():
        raise DataUnavailable(
            f"OARAIM_DATA={env!r} is neither a folder nor an http(s):// or file:// mirror URL; "
            "point it at a data folder or mirror, or unset it to fetch from the public origins")
    return env or None


def checkout_data_dir() -> Path | None:
    """``../shared/data`` beside the source checkout, if it exists."""
    p = REPO_ROOT.parent / "shared" / "data"
    return p if p.is_dir() else None


def data_dir() -> Path | None:
    """The local data folder: ``OARAIM_DATA`` when it is a folder, else ``../shared/data``
    beside the checkout (when ``OARAIM_DATA`` is unset), else None."""
    env = _env_data()
    if env is None:
        return checkout_data_dir()
    return None if _is_url(env) else Path(env).expanduser()


def mirror_url() -> str | None:
    """The mirror base URL when ``OARAIM_DATA`` is one (with a trailing slash), else None."""
    env = _env_data()
    if env and _is_url(env):
        return env if env.endswith("/") else env + "/"
    return None


def source_url(name: str) -> str:
    """Where ``name`` is fetched from: the mirror when ``OARAIM_DATA`` is one, else its origin."""
    base = mirror_url()
    return base + name if base else entry(name).url


def where() -> str:
    """One line: where files are looked for and fetched from, under the current settings."""
    env = _env_data()
    if env and not _is_url(env):
        return f"the folder OARAIM_DATA={env} (nothing is downloaded)"
    cache = cache_dir()
    if env:
        return f"the mirror OARAIM_DATA={env}, fetched into the cache {cache}"
    checkout = checkout_data_dir()
    first = f"{checkout} (beside the checkout), else " if checkout else ""
    return f"{first}the public origins, fetched into the cache {cache}"


def data_required() -> bool:
    """True when tests must fail rather than skip without the data (OARAIM_REQUIRE_DATA=1)."""
    return os.environ.get("OARAIM_REQUIRE_DATA", "") not in ("", "0")


def sha256(path) -> str:
    """Hex sha256 of the file at ``path``, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def trust_data() -> bool:
    """True when local files are used without their checksum (``OARAIM_TRUST_DATA=1``, the
    CLI's ``--trust-data``)."""
    return os.environ.get("OARAIM_TRUST_DATA", "") not in ("", "0")


#: sha256 of local files already hashed, by (resolved path, size, mtime): each costs once
_HASHED: dict = {}


def _hashes_file() -> Path:
    return cache_dir() / "verified.json"


def _cached_sha256(p: Path) -> str:
    """sha256 of ``p``, remembered by (path, size, mtime) in this process and in
    ``CACHE/verified.json``, so a folder file is hashed once, not at every use."""
    st = p.stat()
    key = f"{p.resolve()}|{st.st_size}|{st.st_mtime_ns}"
    if key in _HASHED:
        return _HASHED[key]
    f = _hashes_file()
    try:
        known = json.loads(f.read_text())
    except (OSError, ValueError):
        known = {}
    if not isinstance(known, dict):
        known = {}
    if key not in known:
        known[key] = sha256(p)
        try:
            f.parent.mkdir(parents=True, exist_ok=True)
            tmp = f.with_name(f"{f.name}.{os.getpid()}.tmp")
            tmp.write_text(json.dumps(known, indent=0))
            os.replace(tmp, f)
        except OSError:
            pass  # a read-only cache: hash again next time
    _HASHED[key] = known[key]
    return known[key]


def verified_local(name: str, p: Path) -> Path:
    """``p``, the local copy of registry file ``name``, after its sha256 matched the
    registry's (docs/data.md); ``DataUnavailable`` naming the file and both hashes otherwise,
    unless ``trust_data()``."""
    e = entry(name)
    if trust_data():
        return p
    got = _cached_sha256(p)
    if got != e.sha256:
        raise DataUnavailable(
            f"data file {name} at {p} has sha256 {got}, the registry {e.sha256}: it is not the "
            "published file (edited or damaged); restore it (`oaraim data fetch` into the "
            "cache after removing it), or use it anyway with --trust-data / "
            "OARAIM_TRUST_DATA=1")
    return p


def status(name: str) -> tuple[str, Path | None]:
    """(state, local path) without fetching: state is 'folder' (in the OARAIM_DATA or
    ../shared/data folder, checksum checked: ``verified_local``), 'cached' (in the cache with
    the right checksum) or 'missing'."""
    e = entry(name)
    env = _env_data()
    folder = data_dir()
    if folder is not None and (folder / name).is_file():
        return "folder", verified_local(name, folder / name)
    if env is not None and not _is_url(env):
        return "missing", None  # an OARAIM_DATA folder is the only place looked at
    cached = cache_dir() / name
    if cached.is_file() and cached.stat().st_size == e.size and (
            _cached_sha256(cached) == e.sha256):
        return "cached", cached
    return "missing", None


def _fix(name: str) -> str:
    env = _env_data()
    if env is not None and not _is_url(env):
        return (f"copy it into {env}, point OARAIM_DATA at a folder or mirror URL holding it, "
                f"or unset OARAIM_DATA and run `oaraim data fetch {name}`")
    return (f"run `oaraim data fetch {name}` where the network reaches it, or set OARAIM_DATA "
            "to a folder or mirror URL holding it")


def path(name: str, fetch: bool = True, progress: bool = True) -> Path:
    """A verified local copy of registry file ``name`` (e.g. ``"nav/brdc0010.22n"``).

    Fetches it into the cache when it is neither in the data folder nor cached (``fetch``),
    showing a progress bar on a terminal (``progress``). Raises ``DataUnavailable`` with one
    line naming the file, the reason and the fix.
    """
    state, local = status(name)
    if local is not None:
        return local
    env = _env_data()
    if env is not None and not _is_url(env):
        raise DataUnavailable(f"data file {name} is not in the folder OARAIM_DATA={env}; "
                              + _fix(name))
    if not fetch:
        raise DataUnavailable(f"data file {name} is neither in a data folder nor in the cache "
                              f"{cache_dir()}; " + _fix(name))
    return _download(entry(name), source_url(name), progress)


def link_folder(folder, names=None, progress: bool = False) -> dict[str, str]:
    """Make ``folder`` hold every registry file (or ``names``) at its name (``nav/...``,
    ``obs/...``) as a link to the verified local copy ``path`` gives: from the data folder,
    the cache, or fetched from the mirror or the public origins, exactly as a study gets it.

    Returns ``{name: one-line reason}`` for the files that could not be had (empty when all
    are there); a reason from ``path`` names the file and the fix. Once a source fails to
    answer (``SourceUnreachable``), the remaining files from the same host are not tried
    (each would wait for the same timeout); their reason names the first failure. This is
    how the test suite gets its data (tests/conftest.py).
    """
    folder = Path(folder)
    failed: dict[str, str] = {}
    down: dict[str, str] = {}  # host -> the name whose download failed first
    for name in names if names is not None else registry():
        try:
            host = urllib.parse.urlparse(source_url(name)).netloc or "file://"
            if host in down:
                failed[name] = f"not tried, as {down[host]} could not be fetched from {host}"
                continue
            local = path(name, progress=progress)
        except SourceUnreachable as exc:
            down[host] = name
            failed[name] = str(exc)
            continue
        except DataUnavailable as exc:
            failed[name] = str(exc)
            continue
        link = folder / name
        link.parent.mkdir(parents=True, exist_ok=True)
        link.unlink(missing_ok=True)
        try:
            link.symlink_to(local.resolve())
        except OSError:  # no symbolic links here (some Windows setups): a copy
            shutil.copyfile(local, link)
    return failed


def _reason(exc: BaseException) -> str:
    """A short one-line reason for a failed download."""
    import requests

    if isinstance(exc, requests.HTTPError) and exc.response is not None:
        return f"HTTP {exc.response.status_code} {exc.response.reason}".strip()
    text = str(exc)
    m = re.search(r"\[Errno -?\d+\] [^'\")\]]+", text)
    if m:
        return m.group(0).strip()
    if isinstance(exc, requests.Timeout):
        return f"no answer within {TIMEOUT_S} s"
    return (text.splitlines() or [type(exc).__name__])[0][:200]


def _download(e: DataFile, url: str, progress: bool) -> Path:
    """Fetch ``url`` into the cache as ``e.name``; verified, or nothing is left behind."""
    dest = cache_dir() / e.name
    dest.parent.mkdir(parents=True, exist_ok=True)
    show = progress and sys.stderr.isatty()
    bar = RichDownloadBar(e.name) if show else None
    if url.startswith("file://"):
        try:
            _copy_verified(url, dest, e)
        except OSError as exc:
            raise SourceUnreachable(f"data file {e.name}: copy from {url} failed: "
                                    f"{exc.strerror or exc}; " + _fix(e.name)) from None
        return dest
    import pooch
    import requests

    pooch.get_logger().setLevel("WARNING")
    try:
        pooch.retrieve(url, known_hash=f"sha256:{e.sha256}", fname=dest.name,
                       path=dest.parent, progressbar=False,
                       downloader=pooch.HTTPDownloader(progressbar=bar or False,
                                                       timeout=TIMEOUT_S))
    except requests.RequestException as exc:
        raise SourceUnreachable(f"data file {e.name}: download from {url} failed: "
                                f"{_reason(exc)}; " + _fix(e.name)) from None
    except ValueError as exc:  # pooch: hash mismatch (it removes the download)
        got = re.findall(r"[0-9a-f]{64}", str(exc))
        got = next((g for g in got if g != e.sha256), "?")
        raise DataUnavailable(f"data file {e.name} from {url} failed its checksum: expected "
                              f"sha256 {e.sha256}, got {got} (not kept); the source holds a "
                              "different file: point OARAIM_DATA at a mirror of these exact "
                              "files") from None
    finally:
        if bar is not None:
            bar.close()
    return dest


def _copy_verified(url: str, dest: Path, e: DataFile) -> None:
    src = Path(urllib.request.url2pathname(urllib.parse.urlparse(url).path))
    with tempfile.NamedTemporaryFile(dir=dest.parent, delete=False, prefix=".part-") as tmp:
        tmp_path = Path(tmp.name)
    try:
        shutil.copyfile(src, tmp_path)
        got = sha256(tmp_path)
        if got != e.sha256:
            raise DataUnavailable(f"data file {e.name} from {url} failed its checksum: expected "
                                  f"sha256 {e.sha256}, got {got} (not kept); the source holds "
                                  "a different file: point OARAIM_DATA at a mirror of these "
                                  "exact files")
        os.replace(tmp_path, dest)
    finally:
        tmp_path.unlink(missing_ok=True)


class RichDownloadBar:
    """The progress-bar object pooch's ``HTTPDownloader`` accepts (``total``, ``update(n)``,
    ``reset()``, ``close()``), drawn with rich on stderr; started at the first update."""

    def __init__(self, label: str):
        self.label = label
        self.total = 0
        self._done = 0
        self._progress = None
        self._task = None

    def _start(self):
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            DownloadColumn,
            Progress,
            TextColumn,
            TransferSpeedColumn,
        )

        self._progress = Progress(TextColumn("{task.description}"), BarColumn(),
                                  DownloadColumn(), TransferSpeedColumn(),
                                  console=Console(stderr=True), transient=True)
        self._progress.start()
        self._task = self._progress.add_task(f"fetching {self.label}", total=self.total or None)

    def update(self, n):
        """Advance by ``n`` bytes (pooch's callback); the bar is drawn at the first call."""
        if self._progress is None:
            self._start()
        self._done += n
        self._progress.update(self._task, completed=min(self._done, self.total or self._done))

    def reset(self):
        """Back to 0 bytes of the current ``total`` (pooch calls it at the end, then
        ``update(total)``, so the bar ends full)."""
        self._done = 0
        if self._progress is not None:
            self._progress.reset(self._task, total=self.total or None)

    def close(self):
        """Stop and remove the bar (transient); nothing if it was never drawn."""
        if self._progress is not None:
            self._progress.stop()
            self._progress = None


# ------------------------------------------------------------------ daily broadcast files

#: public IGS archive of daily merged broadcast files (anonymous HTTPS, no login), laid out as
#: BASE/YYYY/DDD/FILE; override with --archive or OARAIM_BRDC_ARCHIVE
BRDC_ARCHIVE = "https://igs.bkg.bund.de/root_ftp/IGS/BRDC/"


def brdc_candidates(year: int, doy: int) -> list[str]:
    """File names of the IGS merged daily broadcast file of a day, preferred first: RINEX 3
    multi-GNSS (``BRDC00IGS_R``, then ``BRDC00WRD_R``, the newer producer code), then the RINEX 2
    GPS file ``brdcDDD0.YYn`` gzip- and Unix-compressed (before December 2020 only ``.Z``)."""
    tag = f"{year:04d}{doy:03d}0000_01D_MN.rnx.gz"
    short = f"brdc{doy:03d}0.{year % 100:02d}n"
    return [f"BRDC00IGS_R_{tag}", f"BRDC00WRD_R_{tag}", f"{short}.gz", f"{short}.Z"]


def fetch_daily_nav(date: str, archive: str | None = None, progress: bool = True) -> Path:
    """The IGS merged daily broadcast navigation file of ``date`` (YYYY-MM-DD) in the cache
    (``CACHE/brdc/``), fetched from ``archive`` (default ``OARAIM_BRDC_ARCHIVE`` or
    ``BRDC_ARCHIVE``) if not cached. A download is kept only once it reads as a RINEX
    navigation file (``_check_downloaded_nav``); otherwise one line names the URL and the
    fault and nothing is cached. No checksum is known beforehand: the sha256 of what was
    downloaded is written beside the file (``FILE.sha256``). Returns the path, which
    ``geometry.load_navigation`` and ``--set nav=PATH`` read as it is."""
    import datetime

    try:
        day = datetime.date.fromisoformat(date.strip())
    except ValueError:
        raise DataUnavailable(f"date must be YYYY-MM-DD (e.g. 2022-01-01), got {date!r}") \
            from None
    if day < datetime.date(1994, 1, 1) or day > datetime.date.today():
        raise DataUnavailable(f"date must be between 1994-01-01 and today for a daily broadcast "
                              f"file, got {date}")
    base = archive or os.environ.get("OARAIM_BRDC_ARCHIVE") or BRDC_ARCHIVE
    if not _is_url(base):
        raise DataUnavailable(f"the broadcast archive must be an http(s):// or file:// URL, got "
                              f"{base!r} (--archive or OARAIM_BRDC_ARCHIVE)")
    base = base if base.endswith("/") else base + "/"
    doy = day.timetuple().tm_yday
    folder = cache_dir() / "brdc"
    names = brdc_candidates(day.year, doy)
    for n in names:
        final = folder / _unz(n)
        side = final.with_name(final.name + ".sha256")
        if final.is_file() and side.is_file():
            recorded = [ln.split()[0] for ln in side.read_text().splitlines()
                        if len(ln.split()) > 1 and ln.split()[1] == final.name]
            got = sha256(final)
            if recorded and recorded[-1] == got:
                return final
            raise DataUnavailable(f"the cached daily broadcast file {final} has sha256 {got}, "
                                  f"its record {side.name} {recorded[-1] if recorded else 'none'}"
                                  ": it changed since it was downloaded; delete both files to "
                                  "fetch it again")
    folder.mkdir(parents=True, exist_ok=True)
    tried = []
    for n in names:
        url = f"{base}{day.year:04d}/{doy:03d}/{n}"
        final = folder / _unz(n)
        part = folder / (".part-" + n)  # never a cached name until it passed the check
        unpacked = folder / (".part-" + final.name)
        try:
            try:
                got = _fetch_unverified(url, part, progress)
            except FileNotFoundError:
                tried.append(f"{n}: not found")
                continue
            except OSError as exc:
                raise DataUnavailable(f"daily broadcast file of {date}: download from {url} "
                                      f"failed: {exc}; check the network or give another "
                                      "archive with --archive URL (or OARAIM_BRDC_ARCHIVE)"
                                      ) from None
            record = f"{got}  {n}  (downloaded from {url})\n"
            if n.endswith(".Z"):  # Unix compress: the RINEX readers take plain or gzip only
                import ncompress

                try:
                    unpacked.write_bytes(ncompress.decompress(part.read_bytes()))
                except Exception as exc:  # noqa: BLE001 - any codec failure is a bad download
                    raise DataUnavailable(f"daily broadcast file of {date}: {url} is not a "
                                          f"valid .Z file ({exc}); nothing was cached; give "
                                          "another archive with --archive URL") from None
                record += f"{sha256(unpacked)}  {final.name}  (decompressed)\n"
            else:
                os.replace(part, unpacked)
            _check_downloaded_nav(unpacked, url, date)
            os.replace(unpacked, final)
        finally:
            part.unlink(missing_ok=True)
            unpacked.unlink(missing_ok=True)
        final.with_name(final.name + ".sha256").write_text(record)
        return final
    raise DataUnavailable(f"no daily broadcast file of {date} (day {doy:03d}) under "
                          f"{base}{day.year:04d}/{doy:03d}/ ({'; '.join(tried)}); give another "
                          "archive with --archive URL (or OARAIM_BRDC_ARCHIVE)")


def _check_downloaded_nav(p: Path, url: str, date: str) -> None:
    """Refuse a download that is not a readable RINEX navigation file (an archive's HTML error
    page, a truncated transfer) before it is cached: the structural check the navigation
    reader itself runs first (``readers.check_navigation_file``), so a file kept
    here is one ``--set nav=PATH`` can read."""
    from oaraim.readers import NavigationFileError, check_navigation_file

    with open(p, "rb") as f:
        head = f.read(40)
    try:
        if p.name.endswith(".gz") and not head.startswith(b"\x1f\x8b"):  # gzip's magic bytes
            raise NavigationFileError(f"{p}: not gzip-compressed, it starts with {head!r}")
        check_navigation_file(p)
    except NavigationFileError as exc:
        why = str(exc).removeprefix(f"{p}: ")
        raise DataUnavailable(f"daily broadcast file of {date}: {url} is not a RINEX "
                              f"navigation file ({why}); nothing was cached; give another "
                              "archive with --archive URL (or OARAIM_BRDC_ARCHIVE)") from None


def _unz(name: str) -> str:
    return name[:-2] if name.endswith(".Z") else name


def _fetch_unverified(url: str, dest: Path, progress: bool) -> str:
    """Download ``url`` to ``dest`` (atomically); returns its sha256. A missing file raises
    FileNotFoundError, any other failure OSError with a one-line reason."""
    tmp = dest.with_name(".part-" + dest.name)
    try:
        if url.startswith("file://"):
            src = Path(urllib.request.url2pathname(urllib.parse.urlparse(url).path))
            if not src.is_file():
                raise FileNotFoundError(url)
            shutil.copyfile(src, tmp)
        else:
            import pooch
            import requests

            bar = RichDownloadBar(dest.name) if progress and sys.stderr.isatty() else None
            try:
                pooch.HTTPDownloader(progressbar=bar or False, timeout=TIMEOUT_S)(
                    url, str(tmp), None)
            except requests.HTTPError as exc:
                if exc.response is not None and exc.response.status_code == 404:
                    raise FileNotFoundError(url) from None
                raise OSError(_reason(exc)) from None
            except requests.RequestException as exc:
                raise OSError(_reason(exc)) from None
            finally:
                if bar is not None:
                    bar.close()
        got = sha256(tmp)
        os.replace(tmp, dest)
        return got
    finally:
        tmp.unlink(missing_ok=True)
