"""The studies of a suite run through the results cache (:mod:`harness.running.result_cache`): studies whose
inputs are unchanged are read back instead of rendered and timed again.

The key is a SHA-256 over the run's cases (each record's name and ``cache_key``: the key of its outcome, so every
scene, setting, ground truth and renderer behind it), the study options (but the cache folder and the progress
bar), the suite's name and file, the Mitsuba variant the studies resolve, and the code digest and environment
of :mod:`harness.running.result_cache`. A run with a case that has no key (a time budget, an external renderer,
an error, ``--no-cache``) has no studies key: its studies are always computed.

The studies time renders, so a cached study's figures are the timings of the run that measured them: the
studies.json read back says so (``"cached": {"from": <that run's started time>, "generated": ..., "key": ...}``)
and its ``note``, which the report shows at the top of the page, says "studies measured <date>, cached".
"""

from __future__ import annotations

import json
import time
from pathlib import Path, PurePosixPath

from harness.core import jsonsafe
from harness.core.errors import HarnessError
from harness.files.entries import EntryStore
from harness.files.imageio import StagedFolder, atomic_write_bytes, atomic_write_text, make_folders
from harness.files.studies import STUDIES_FILE, STUDIES_KIND, studies_folder
from harness.renderers.mitsuba import choose_variant
from harness.running import result_cache
from harness.studies.suite_studies import StudyOptions, write_suite_studies


def _variant(requested: str | None) -> str:
    try:
        return choose_variant(requested)
    except HarnessError as err:  # no Mitsuba: the studies say so in their sections
        return f"unavailable: {err}"


def studies_key(results: dict, options: StudyOptions) -> str | None:
    """The key of the studies of the run ``results`` with ``options``, or None when a case has no cache key."""
    records = results.get("cases") or []
    if not records or not all(isinstance(r, dict) and isinstance(r.get("cache_key"), str) for r in records):
        return None
    return result_cache.key_of({
        "format": result_cache.FORMAT, "kind": "studies",
        "suite": results.get("suite"), "suite_file": results.get("suite_file"),
        "cases": [[r.get("name"), r["cache_key"]] for r in records],
        "options": {k: v for k, v in options.to_json().items() if k != "cache_dir"},
        "variant": _variant(options.variant),
        "code": result_cache.code_digest(), "environment": result_cache.environment(),
    })


def cached_suite_studies(results: dict, results_dir: str | Path, options: StudyOptions | None = None, *,
                         mode: str = "use", out_dir: str | Path | None = None,
                         results_file: str | Path | None = None) -> dict:
    """:func:`harness.studies.suite_studies.write_suite_studies` through the results cache (``mode``: one of
    :data:`harness.running.result_cache.MODES`). Returns its dict, with ``"cached"`` (where the studies came
    from) on a hit and ``"key"`` (None when the studies are not cacheable)."""
    options = options or StudyOptions()
    target = Path(out_dir) if out_dir is not None else studies_folder(results_dir)
    key = studies_key(results, options) if mode != "off" else None
    store = result_cache.store_for(options.cache_dir)
    if key is not None and mode == "use":
        hit = _restore(store, key, results, target, results_file)
        if hit is not None:
            return hit
    before = result_cache.snapshot(target)
    paths = write_suite_studies(results, results_dir, options, out_dir=target, results_file=results_file)
    if key is not None:
        meta = {"kind": "studies", "suite": results.get("suite"), "started": results.get("started")}
        store.store(key, meta, result_cache.written_since(target, before), replace=mode == "refresh")
    return dict(paths, key=key)


def _restore(store: EntryStore, key: str, results: dict, target: Path, results_file) -> dict | None:
    """The cached studies of ``key`` written into ``target`` (all or nothing, as the studies are), studies.json
    marked as cached; None on a miss."""
    start = time.perf_counter()
    entry = store.load(key)
    contents = store.read_files(entry) if entry is not None else None
    if contents is None:
        return None
    try:
        doc = json.loads(contents[STUDIES_FILE])
        if not isinstance(doc, dict) or doc.get("kind") != STUDIES_KIND:
            raise ValueError("not a studies file")
    except (KeyError, ValueError, UnicodeDecodeError, RecursionError):
        store.discard(key)
        return None
    measured = entry.meta.get("started") or doc.get("started")
    cached = {"from": measured, "generated": doc.get("generated"), "key": key}
    note = (f"studies measured {measured}, cached: their timings are that run's (harness run --fresh measures "
            "them again)")
    doc.update(started=results.get("started"), results_file=str(results_file) if results_file else None,
               cached=cached, note="; ".join(n for n in (doc.get("note"), note) if isinstance(n, str) and n))
    with StagedFolder(target, str(target), replace_link=True) as stage:  # a link at studies/ is not followed
        for name, data in sorted(contents.items()):
            if name != STUDIES_FILE:
                path = Path(stage.root, *PurePosixPath(name).parts)
                make_folders(path.parent)
                atomic_write_bytes(path, data)
        atomic_write_text(stage.root / STUDIES_FILE, jsonsafe.dumps(doc, indent=2))
        stage.commit(last=(STUDIES_FILE,))
    return {"studies_json": target / STUDIES_FILE, "folder": target, "seconds": time.perf_counter() - start,
            "cached": cached, "key": key}
