"""The report's summary table: a long reason is cut at a word with an ellipsis, a renderer file is named by its
file name; the whole reason and the file's path are the cells' titles."""

from __future__ import annotations

from types import SimpleNamespace

from harness.report import build
from harness.report.labels import clip, renderer_label

REASON = ("verdict fail: 14 of 64 tiles differ beyond alpha = 0.001 (max |z| 7.52 at tile (3, 5), channel B); "
          "global bias z = 4.1; the render's mean is 2.3 % above the ground truth's")


def _row(record: dict) -> dict:
    return build._summary_row(SimpleNamespace(record=record, index=0))


def test_reason_cut_at_a_word_with_an_ellipsis_and_whole_in_the_title():
    row = _row({"name": "toy/depth", "scene": "/s/cornell-box.toml", "renderer": "reference", "reason": REASON})
    assert row["reason"].endswith("…") and len(row["reason"]) <= 120
    shown = row["reason"][:-1]
    assert REASON.startswith(shown) and not REASON[len(shown)].isalnum(), row["reason"]  # whole words only
    assert row["reason_title"] == REASON


def test_a_short_reason_is_whole_and_has_no_title():
    row = _row({"name": "a", "scene": "s.toml", "renderer": "reference", "reason": "timed out after 12 s"})
    assert row["reason"] == "timed out after 12 s" and row["reason_title"] is None


def test_a_renderer_file_is_labelled_by_its_name_with_the_path_as_title():
    path = "/home/someone/renderers/toy.toml"
    row = _row({"name": "a", "scene": "s.toml", "renderer": path, "reason": ""})
    assert row["renderer"] == "toy.toml" and row["renderer_title"] == path
    row = _row({"name": "b", "scene": "s.toml", "renderer": "mitsuba", "reason": ""})
    assert row["renderer"] == "mitsuba" and row["renderer_title"] is None


def test_the_table_template_gives_both_cells_a_title():
    text = (build.Path(build.__file__).parent / "templates" / "suite.html.j2").read_text()
    assert 'title="{{ row.reason_title }}"' in text and 'title="{{ row.renderer_title }}"' in text


def test_clip_never_cuts_inside_a_word():
    assert clip("alpha beta gamma", 12) == "alpha beta…"
    assert clip("x" * 50, 10) == "x" * 9 + "…"
    assert renderer_label(None) is None
