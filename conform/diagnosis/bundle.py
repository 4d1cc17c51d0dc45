"""One file to send to someone: ``conform bundle CAPTURE… -o FILE.zip``.

The zip holds ``manifest.json`` (what is inside, the conform version, the OS and Python, the
serial ports the captures name with their description and USB VID:PID where this machine
knows them), ``captures/`` (the capture files), ``diagnosis/`` (each capture's diagnosis as
JSON and text), ``analysis/<capture>/`` (its analysis report) and ``tables/<capture>/`` (its
Parquet tables). ``--redact`` replaces the host name, the user name and home and capture
folders in everything but the recorded traffic, and leaves out USB serial numbers;
``conform analyze FILE.zip`` opens a bundle again (:func:`expand_bundles`).
"""

from __future__ import annotations

import atexit
import getpass
import hashlib
import json
import os
import platform
import re
import shutil
import socket
import sys
import tempfile
import zipfile
from collections.abc import Callable, Iterable
from datetime import UTC, datetime
from pathlib import Path

from conform import __version__
from conform.capture.scan import check_magic
from conform.errors import UserError
from conform.jsondoc import JsonObject

FORMAT = "conform-bundle/1"
MANIFEST = "manifest.json"
TEXT_SUFFIXES = (".json", ".md", ".html", ".txt")
RAW_TOPICS_KEEP = ("/raw/", "/serial/")      # the traffic itself is never rewritten
_VIDPID = re.compile(r"VID:PID=([0-9A-Fa-f]{4}):([0-9A-Fa-f]{4})")


def redactions(captures: Iterable[str]) -> list[tuple[str, str]]:
    """(text, replacement) pairs, longest first: folders, then host and user names."""
    pairs = [(str(Path(c).resolve().parent), "<capture-dir>") for c in captures]
    home = str(Path.home())
    pairs.append((home, "~"))
    for name, tag in ((socket.gethostname(), "<host>"), (_user(), "<user>")):
        if name and len(name) >= 2:
            pairs.append((name, tag))
    seen: dict[str, str] = {}
    for a, b in pairs:
        if a and a not in ("/", "."):
            seen.setdefault(a, b)
    return sorted(seen.items(), key=lambda p: -len(p[0]))


def _user() -> str:
    try:
        return getpass.getuser()
    except Exception:  # noqa: BLE001 - no user name to hide
        return ""


def _apply(text: str, subs: list[tuple[str, str]]) -> str:
    for a, b in subs:
        text = text.replace(a, b)
    return text


def redact_capture(src: str, dst: Path, subs: list[tuple[str, str]], extra: dict[str, str]
                   ) -> None:
    """A copy of a capture with the metadata, log and link messages redacted (the raw and
    decoded traffic as recorded). ``extra``: metadata values to replace by key."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as fin, open(dst, "wb") as fout:
        reader = make_reader(fin)
        header = reader.get_header()
        w = Writer(fout)
        w.start(profile=header.profile, library=header.library)
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, msg in reader.iter_messages(log_time_order=False):
            if channel.id not in channels:
                if schema is not None and schema.id not in schemas:
                    schemas[schema.id] = w.register_schema(schema.name, schema.encoding,
                                                           schema.data)
                channels[channel.id] = w.register_channel(
                    channel.topic, channel.message_encoding,
                    schemas.get(schema.id, 0) if schema is not None else 0,
                    dict(channel.metadata))
            data = msg.data
            if not channel.topic.startswith(RAW_TOPICS_KEEP):
                data = _apply(data.decode("utf-8", "replace"), subs).encode()
            w.add_message(channels[channel.id], msg.log_time, data, msg.publish_time,
                          msg.sequence)
        for m in reader.iter_metadata():
            meta = {k: extra.get(k, _apply(v, subs)) for k, v in m.metadata.items()}
            w.add_metadata(m.name, meta)
        w.finish()


def serial_ports(named: set[str], redact: bool) -> list[JsonObject]:
    """This machine's serial ports (pyserial), those the captures name first."""
    try:
        from conform.cli.ports_cmd import listed_ports

        ports = listed_ports()
    except Exception:  # noqa: BLE001 - no listing on this platform
        ports = []
    out = []
    for p in ports:
        m = _VIDPID.search(p.hwid)
        hwid = re.sub(r"\s*(SER|LOCATION)=\S*", "", p.hwid) if redact else p.hwid
        out.append({"device": p.device, "description": p.description, "hwid": hwid,
                    "usb_vid_pid": f"{m.group(1)}:{m.group(2)}".upper() if m else None,
                    "named_by_capture": p.device in named})
    listed = {p["device"] for p in out}
    out += [{"device": d, "description": "not present on this machine now (or a pty)",
             "hwid": "", "usb_vid_pid": None, "named_by_capture": True}
            for d in sorted(named - listed)]
    return sorted(out, key=lambda p: not p["named_by_capture"])


def _analysis(path: str, report: Path, tables: Path) -> None:
    """The capture's analysis report and tables, by its family (as ``conform analyze``)."""
    from conform.families.peek import detect_capture

    d = detect_capture(path, None)
    if d is None:
        from conform.analysis import analyze
        from conform.analysis.report import write_report

        write_report(analyze(path, parquet=str(tables)), str(report))
    elif d.family != "unknown":
        from conform.families import family

        a = family(d.family).analyze(path, detected=d.why)
        a.write_report(str(report))
        a.write_tables(str(tables))


def write_bundle(captures: list[str], output: str, *, redact: bool = False, force: bool = False,
                 echo: Callable[[str], None] = print) -> Path:
    from conform.diagnosis import diagnose
    from conform.diagnosis.render import text_lines

    out = Path(output)
    if out.exists() and not force:
        raise UserError(f"{out}: exists; choose another name or pass --force")
    for c in captures:
        if Path(c).resolve() == out.resolve():
            raise UserError(f"{out}: is one of the captures; the bundle goes elsewhere")
        check_magic(c)   # not a capture at all: one line now, not a bundle of errors
    from conform.capture.reader import open_capture

    for c in captures:      # a file that is not a capture is refused, not packed
        open_capture(c).metadata  # noqa: B018 - reading it raises UserError for a non-capture
    subs = redactions(captures) if redact else []
    work = Path(tempfile.mkdtemp(prefix="conform-bundle-"))
    try:
        entries = []
        named: set[str] = set()
        used: set[str] = set()
        for c in captures:
            name = Path(c).name
            stem = Path(c).stem
            k = 1
            while name in used:
                k += 1
                name, stem = f"{Path(c).stem}-{k}{Path(c).suffix}", f"{Path(c).stem}-{k}"
            used.add(name)
            entry: dict[str, object] = {"name": name, "bytes": os.path.getsize(c)}
            (work / "captures").mkdir(exist_ok=True)
            if redact:
                try:
                    redact_capture(c, work / "captures" / name, subs,
                                   {"hostname": "<host>"})
                except Exception as exc:  # noqa: BLE001 - unreadable: left out, not leaked
                    entry["left_out"] = f"cannot be redacted: {type(exc).__name__}: {exc}"
                    echo(f"{c}: left out of the bundle ({entry['left_out']})")
            else:
                shutil.copyfile(c, work / "captures" / name)
            if "left_out" not in entry:
                entry["sha256"] = hashlib.sha256(
                    (work / "captures" / name).read_bytes()).hexdigest()
            try:
                d = diagnose(c)
                doc = d.to_json()
                entry |= {"family": doc["family"], "variant": doc["variant"],
                          "headline": doc["headline"]}
                (work / "diagnosis").mkdir(exist_ok=True)
                (work / "diagnosis" / f"{stem}.json").write_text(json.dumps(doc, indent=1,
                                                                            default=str))
                (work / "diagnosis" / f"{stem}.txt").write_text("\n".join(text_lines(d)) + "\n")
            except UserError as exc:
                entry["diagnosis_error"] = str(exc)
            try:
                _analysis(c, work / "analysis" / stem, work / "tables" / stem)
            except UserError as exc:
                entry["analysis_error"] = str(exc)
            named |= _ports_named(c)
            entries.append(entry)
        manifest = {
            "format": FORMAT, "created": datetime.now(UTC).isoformat(),
            "conform_version": __version__,
            "python": sys.version.split()[0], "implementation": platform.python_implementation(),
            "os": platform.platform(), "machine": platform.machine(),
            "redacted": redact, "captures": entries,
            "serial_ports": serial_ports(named, redact),
        }
        (work / MANIFEST).write_text(json.dumps(manifest, indent=1, default=str))
        if redact:
            for f in work.rglob("*"):
                if f.suffix in TEXT_SUFFIXES and f.is_file():
                    f.write_text(_apply(f.read_text(encoding="utf-8", errors="replace"), subs))
        part = out.with_name(out.name + ".part")
        try:
            with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as z:
                for f in sorted(work.rglob("*")):
                    if f.is_file():
                        z.write(f, f.relative_to(work).as_posix())
            part.replace(out)
        except OSError as exc:
            part.unlink(missing_ok=True)
            raise UserError(f"{out}: cannot write the bundle: {exc.strerror or exc}") from None
        return out
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _ports_named(path: str) -> set[str]:
    """The serial ports a capture's session metadata names."""
    from conform.families.peek import peek_capture

    try:
        meta = peek_capture(path, 0)[2]
    except Exception:  # noqa: BLE001 - a damaged capture names none we can read
        return set()
    return {str(meta[k]) for k in ("host_port", "unit_port") if meta.get(k)}


def is_bundle(path: str) -> bool:
    if not str(path).lower().endswith(".zip") or not zipfile.is_zipfile(path):
        return False
    with zipfile.ZipFile(path) as z:
        return MANIFEST in z.namelist()


def open_bundle(path: str) -> tuple[JsonObject, list[str]]:
    """The manifest and the captures of a bundle, extracted to a folder removed at exit."""
    try:
        with zipfile.ZipFile(path) as z:
            manifest = json.loads(z.read(MANIFEST))
            if manifest.get("format") != FORMAT:
                raise UserError(f"{path}: not a conform bundle ({manifest.get('format')!r})")
            top = Path(tempfile.mkdtemp(prefix="conform-bundle-"))
            atexit.register(shutil.rmtree, top, True)
            work = top / Path(path).stem        # a fleet names the machine by the folder
            work.mkdir()
            out = []
            for info in z.infolist():
                parts = Path(info.filename).parts
                if len(parts) == 2 and parts[0] == "captures" and not info.is_dir():
                    target = work / Path(parts[1]).name      # never outside the folder
                    target.write_bytes(z.read(info))
                    out.append(str(target))
    except (zipfile.BadZipFile, KeyError, ValueError, OSError) as exc:
        raise UserError(f"{path}: not a readable conform bundle: {exc}") from None
    if not out:
        raise UserError(f"{path}: the bundle holds no capture")
    return manifest, sorted(out)


def expand_bundles(files: Iterable[str], echo: Callable[[str], None]) -> tuple[str, ...]:
    """``files`` with every bundle replaced by its captures (and said what it is)."""
    out: list[str] = []
    for f in files:
        if not is_bundle(f):
            out.append(f)
            continue
        manifest, captures = open_bundle(f)
        echo(f"{f}: bundle of {len(captures)} capture(s) made by conform "
             f"{manifest.get('conform_version')} on {manifest.get('os')}, Python "
             f"{manifest.get('python')}" + (" (redacted)" if manifest.get("redacted") else ""))
        for c in manifest.get("captures", []):
            if c.get("headline"):
                echo(f"  {c['name']}: {c['headline']}")
        out += captures
    return tuple(out)
