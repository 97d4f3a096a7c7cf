"""JUnit XML of a suite run, for CI systems (GitLab, Jenkins, GitHub test reporters): ``harness run --junit FILE``.

One ``<testsuite>`` (inside ``<testsuites>``) per run, one ``<testcase>`` per case:

- ``name`` = the case name, ``classname`` = ``<suite>.<scene>`` (Jenkins groups by the dots), ``file`` = the scene
  file, ``time`` = the case's wall seconds (ground truth, render and comparison).
- a case that ended as expected has no child but ``<properties>`` and ``<system-out>``; an ``expect = "fail"``
  case (a planted fault) that failed is a *passed* test: the harness proved its verdict sharp, so it is reported,
  not skipped (``<system-out>`` says "failed as expected").
- ``<failure type="verdict" | "baseline" | "planted-fault-not-caught">`` with the reason as ``message``, for a case
  not as expected: the verdict or a threshold failed a ``pass`` case, only the baseline regressed, or a planted
  fault passed.
- ``<error type="<exception name>">`` for a case whose renderer raised (status ``error``), the traceback as text.
- ``<skipped message="...">`` for a case this machine cannot run (status ``skipped``: a Mitsuba variant it
  ``requires`` is not usable here), the reason as ``message``.
- ``<properties>``: status, expect, verdict, the global-bias z per channel, the omnibus and max |z| p-values, the
  worst tile's z, relMSE and RMSE, and the baseline ratios where compared (pytest's xunit1 places testcase
  properties the same way; GitLab ignores them, Jenkins shows them).

Characters XML 1.0 cannot hold (control characters in a traceback) are replaced; the file is written atomically.
"""

from __future__ import annotations

import re
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

from harness.core.errors import HarnessError
from harness.files.imageio import atomic_write_bytes

_XML_BAD = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ufffe\uffff]")


def _text(value) -> str:
    return _XML_BAD.sub("?", str(value))


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return _text(value)


def _properties(parent: ET.Element, pairs: list[tuple[str, object]]) -> None:
    props = ET.SubElement(parent, "properties")
    for name, value in pairs:
        if value is not None:
            ET.SubElement(props, "property", name=name, value=_fmt(value))


def _case_properties(record: dict) -> list[tuple[str, object]]:
    pairs: list[tuple[str, object]] = [("status", record.get("status")), ("expect", record.get("expect"))]
    verdict = record.get("verdict") or {}
    if verdict:
        pairs.append(("verdict", verdict.get("verdict")))
        for channel, z in zip("RGB", (verdict.get("global_bias") or {}).get("z") or []):
            pairs.append((f"global_bias.z.{channel}", z))
        pairs.append(("global_bias.p", (verdict.get("global_bias") or {}).get("p_value")))
        pairs.append(("omnibus.p", (verdict.get("omnibus") or {}).get("p_value")))
        pairs.append(("max_z", (verdict.get("max_z") or {}).get("statistic")))
        pairs.append(("max_z.p", (verdict.get("max_z") or {}).get("p_value")))
        worst = verdict.get("worst_tile") or {}
        if worst:
            pairs.append(("worst_tile", f"y={worst.get('y')} x={worst.get('x')} {worst.get('channel')} "
                                        f"z={_fmt(worst.get('z'))}"))
    metrics = record.get("metrics") or {}
    for name in ("relmse", "rmse"):
        pairs.append((name, metrics.get(name)))
    for check in (record.get("baseline") or {}).get("checks", []):
        if "z" in check:  # bias: the shift of the image mean from the baseline's, in standard errors
            pairs.append((f"baseline.{check['metric']}.z", check["z"]))
        elif check.get("baseline"):
            pairs.append((f"baseline.{check['metric']}.ratio", check["value"] / check["baseline"]))
    return pairs


def _failure(record: dict) -> tuple[str, str] | None:
    """(type, message) of a case not as expected whose status is pass or fail."""
    if record.get("ok") or record.get("status") in ("error", "skipped"):
        return None
    if record.get("expect") == "fail" and record.get("status") == "pass":
        return "planted-fault-not-caught", "expected the verdict to fail (a planted fault), but it passed"
    regressions = (record.get("baseline") or {}).get("regressions") or []
    kind = "baseline" if regressions and record.get("status") == record.get("expect") else "verdict"
    return kind, record.get("reason") or kind


def build(results: dict) -> ET.ElementTree:
    """The JUnit document of a ``results.json`` dict (see ``docs/results-schema.md``)."""
    suite = results.get("suite", "suite")
    records = results.get("cases", [])
    failures = sum(1 for r in records if _failure(r) is not None)
    errors = sum(1 for r in records if r.get("status") == "error")
    skipped = sum(1 for r in records if r.get("status") == "skipped")
    total_time = sum(float(r.get("wall_seconds") or 0.0) for r in records)
    counts = {"tests": str(len(records)), "failures": str(failures), "errors": str(errors), "skipped": str(skipped),
              "time": f"{total_time:.3f}"}
    root = ET.Element("testsuites", name="harness", **counts)
    started = str(results.get("started", ""))[:19]  # ISO 8601 without the zone, as the JUnit schema wants
    attrs = dict(name=_text(suite), **counts, hostname=_text((results.get("host") or {}).get("node", "")))
    if started:
        attrs["timestamp"] = started
    ts = ET.SubElement(root, "testsuite", **attrs)
    suite_props = [("suite_file", results.get("suite_file"))]
    if results.get("baseline"):
        suite_props.append(("baseline", results["baseline"].get("file")))
    _properties(ts, suite_props)
    for record in records:
        scene = Path(str(record.get("scene", ""))).stem or "case"
        tc = ET.SubElement(ts, "testcase", name=_text(record.get("name", "")), classname=_text(f"{suite}.{scene}"),
                           file=_text(record.get("scene", "")), time=f"{float(record.get('wall_seconds') or 0.0):.3f}")
        _properties(tc, _case_properties(record))
        failure = _failure(record)
        if record.get("status") == "skipped":
            ET.SubElement(tc, "skipped", message=_text(record.get("reason", "skipped")))
        elif record.get("status") == "error":
            reason = record.get("reason", "error")
            el = ET.SubElement(tc, "error", message=_text(reason), type=_text(reason.split(":")[0] or "error"))
            el.text = _text(record.get("traceback", reason))
        elif failure is not None:
            el = ET.SubElement(tc, "failure", message=_text(failure[1]), type=failure[0])
            el.text = _text(_details(record))
        out = ET.SubElement(tc, "system-out")
        out.text = _text(_details(record))
    ET.indent(root)
    return ET.ElementTree(root)


def _details(record: dict) -> str:
    status, expect = record.get("status"), record.get("expect")
    head = f"{record.get('name')}: {status} (expected {expect})"
    if status == "fail" and expect == "fail" and record.get("ok"):
        head += ": failed as expected"
    lines = [head]
    if record.get("reason"):
        lines.append(f"reason: {record['reason']}")
    verdict = record.get("verdict") or {}
    if verdict.get("reason") and verdict.get("reason") != record.get("reason"):
        lines.append(f"verdict: {verdict['reason']}")
    note = (record.get("baseline") or {}).get("note")
    if note:
        lines.append(f"baseline: {note}")
    if record.get("render", {}).get("exr"):
        lines.append(f"render: {record['render']['exr']}")
    return "\n".join(lines)


def write(results: dict, path: str | Path) -> Path:
    """Write the JUnit XML of ``results`` to ``path`` atomically."""
    tree = build(results)
    data = ET.tostring(tree.getroot(), encoding="utf-8", xml_declaration=True)
    return atomic_write_bytes(path, data + b"\n")


def check_writable(path: str | Path, option: str = "--junit") -> None:
    """Before a run: create the output's folder (like ``--out``), or refuse with a one-line error."""
    if Path(path).is_dir():
        raise HarnessError(option, f"{str(path)!r} is a folder; expected a file name, e.g. junit.xml")
    folder = Path(path).parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise HarnessError(option, f"cannot create the folder {str(folder)!r}: {err.strerror}") from None
    try:  # a real write, as the atomic write at the end will do (permission bits alone say nothing to root)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".junit-probe-"):
            pass
    except OSError as err:
        raise HarnessError(option, f"cannot write in the folder {str(folder)!r}: {err.strerror}") from None
