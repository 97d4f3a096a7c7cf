"""The report's comparison viewer, on the Python side: the run makes each case's viewer files and the report links
them (rendering nothing); a results.json of an older harness still gets them, made by the report with the run's
tiles; the page embeds one thumbnail per case, not its images; the page's colour maps are matplotlib's."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from test_viewer_data import decode, read_script

from harness.files import viewer_data
from harness.files.results import read_results
from harness.report import viewer as report_viewer
from harness.report import write_suite_report
from harness.running.cases import load_suite
from harness.running.schedule import run_suite

pytestmark = pytest.mark.slow  # renders

SUITE = """
name = "viewer"
[defaults]
spp = 4
film = { width = 24, height = 16 }

[[cases]]
name = "furnace/closed-form"
scene = "SCENES/furnace.toml"

[[cases]]
name = "furnace/</script><b>mutant</b>"
scene = "SCENES/furnace.toml"
settings = { mutant = "double-emission" }
expect = "fail"
"""


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("viewer")
    (folder / "s.toml").write_text(SUITE.replace("SCENES", str(ROOT / "scenes")))
    out = folder / "out"
    run_suite(load_suite(folder / "s.toml"), out)
    write_suite_report(out / "results.json", out)
    return out


def test_the_run_writes_the_viewer_files_and_the_report_copies_them(run_dir):
    results = read_results(run_dir / "results.json")  # the schema takes the record's "viewer"
    report = json.loads((run_dir / "report.json").read_text())
    page = (run_dir / "index.html").read_text()
    for record, case in zip(results["cases"], report["cases"]):
        entry = record["viewer"]
        folder = Path(entry["folder"])
        assert folder == run_dir / "cases" / folder.name and entry["data"] == viewer_data.DATA_FILE
        payload = read_script((folder / entry["data"]).read_text())
        assert payload["name"] == record["name"] and (payload["width"], payload["height"]) == (24, 16)
        assert sum(entry["p_histogram"]["counts"]) == entry["p_histogram"]["tested"] > 0
        for key in ("data", "thumbnail", "pvalue"):  # checked copies in report/<case>/ (viewer.js written again)
            placed = Path(case["viewer"][key])
            assert placed.parent == run_dir / "report" / placed.parent.name
            assert placed.read_bytes() == (folder / entry[key]).read_bytes()
            assert placed.stat().st_ino != (folder / entry[key]).stat().st_ino
        assert case["viewer"]["p_histogram"] == entry["p_histogram"]
        src = f"report/{Path(case['viewer']['data']).parent.name}/viewer.js"
        assert f'data-viewer-src="{src}"' in page
    # the page embeds each case's two thumbnails, not its five images; its histogram is inline SVG
    assert page.count('alt="render of ') == page.count('alt="tile p-values of ') == 2
    assert page.count("data:image/png;base64,") == 4 and page.count('<svg class="hist"') == 2
    failing = results["cases"][1]["viewer"]["p_histogram"]
    assert failing["counts"][0] == failing["tested"] and failing["failing"] == 6  # every tile: p near 0
    # the hostile name is a string in the data and escaped in the page
    assert "</script><b>" not in page.split('id="cases"', 1)[1].split("<template", 1)[0]
    assert "&lt;/script&gt;&lt;b&gt;mutant&lt;/b&gt;" in page


def test_an_older_results_json_gets_viewer_files_made_by_the_report(run_dir, tmp_path):
    """No ``viewer`` in the records (a run by an older harness): the report makes the files from the case's EXRs,
    with the tiles of the verdict computed again as the run computed them."""
    results = json.loads((run_dir / "results.json").read_text())
    for record in results["cases"]:
        record.pop("viewer")
    old = tmp_path / "old"
    (run_dir / "results-older.json").write_text(json.dumps(results))  # in the run folder, whose files it names
    write_suite_report(run_dir / "results-older.json", old)
    report = json.loads((old / "report.json").read_text())
    for record, case in zip(json.loads((run_dir / "results.json").read_text())["cases"], report["cases"]):
        assert case["problems"] == [] and case["viewer"] is not None
        made = read_script(Path(case["viewer"]["data"]).read_text())
        ran = read_script((Path(record["viewer"]["folder"]) / "viewer.js").read_text())
        assert made["tiles"]["recomputed"] and not ran["tiles"]["recomputed"]
        shape = (made["tiles"]["rows"], made["tiles"]["cols"], 3)
        for key in ("z", "p", "tested", "failing"):
            np.testing.assert_allclose(decode(made["tiles"][key], shape), decode(ran["tiles"][key], shape),
                                       rtol=1e-6, atol=0)
        assert made["planes"] == ran["planes"]  # the same images, the same FLIP map
        assert case["viewer"]["p_histogram"] == record["viewer"]["p_histogram"]
        assert Path(case["viewer"]["data"]).stat().st_ino != (Path(record["viewer"]["folder"]) /
                                                               "viewer.js").stat().st_ino  # made, not linked
    assert (old / "index.html").read_text().count("data-viewer-src=") == 2


def test_the_page_s_colour_maps_are_matplotlib_s():
    import matplotlib

    from harness.files.previews import css_stops

    script = (Path(report_viewer.__file__).parent / "static" / "viewer_colormaps.js").read_text()
    for name in ("RdBu_r", "viridis", "magma"):
        block = re.search(name + r': ("[^;]*?")\s*[,}]', script, re.S).group(1)
        stops = "".join(re.findall(r'"([^"]*)"', block)).split()
        ours = np.array([[int(h[i:i + 2], 16) for i in (0, 2, 4)] for h in stops], float)
        theirs = matplotlib.colormaps[name](np.linspace(0, 1, len(stops)))[:, :3] * 255
        assert len(stops) == 33 and np.abs(ours - theirs).max() <= 0.5 + 1e-9, name
        # linear interpolation between the 33 stops stays within 4 of 255 levels of the 256-colour map (RdBu_r
        # bends most)
        t = np.linspace(0, 1, 256)
        between = np.stack([np.interp(t * 32, np.arange(33), ours[:, c]) for c in range(3)], axis=-1)
        assert np.abs(between - matplotlib.colormaps[name](t)[:, :3] * 255).max() <= 4, name
    assert report_viewer.MAGMA_STOPS == ", ".join(css_stops("magma"))


def test_the_histogram_view_draws_what_it_counts():
    view = report_viewer.histogram_view({"bins": 4, "counts": [8, 0, 2, 2], "tested": 12, "failing": 1})
    box = view["box"]
    bars = [re.fullmatch(r"M([\d.]+) ([\d.]+)V([\d.]+)H([\d.]+)V([\d.]+)", b).groups()
            for b in (view["low"] + view["bars"]).split("Z")[:-1]]
    heights = [float(b[1]) - float(b[2]) for b in bars]
    assert len(bars) == 4 and heights[0] == box["bottom"] - box["top"]  # the tallest bar fills the box
    assert heights[1] == 0 and heights[2] == heights[3] == pytest.approx(heights[0] / 4)
    assert box["top"] < view["expected_y"] < box["bottom"] and view["expected"] == 3.0 and view["counts"] == "8, 0, 2, 2"
    assert report_viewer.histogram_view(None) is None
    assert report_viewer.histogram_view({"counts": [1, "x"], "tested": 0}) is None


def test_tiles_again_raises_the_verdicts_image_errors_as_harness_errors():
    """A run folder's render with a NaN variance, or a ground truth with a NaN pixel: the verdict's ValueError about
    that image reaches the report as the HarnessError naming it, with the same text; a bad tile stays a ValueError."""
    from harness.core.errors import HarnessError
    from harness.files.cases import GroundTruthImage

    image, zero = np.ones((16, 24, 3)), np.zeros((16, 24, 3))
    nan_var, bad = zero.copy(), image.copy()
    nan_var[2, 3, 1], bad[4, 5, 0] = np.nan, np.nan
    record = {"tile": 8, "alpha": 0.001}
    with pytest.raises(HarnessError, match=r"^test image: variance is NaN, infinite or negative at 1 pixels") as info:
        report_viewer.tiles_again(image, nan_var, GroundTruthImage(image, zero, "closed-form", 0), record)
    assert info.value.where == "test image"
    with pytest.raises(HarnessError, match=r"^ground truth image: 1 non-finite \(NaN/Inf\) pixels") as info:
        report_viewer.tiles_again(image, zero, GroundTruthImage(bad, zero, "mitsuba", 64), record)
    assert info.value.where == "ground truth image"
    with pytest.raises(ValueError, match="tile must be a positive integer"):
        report_viewer.tiles_again(image, zero, GroundTruthImage(image, zero, "closed-form", 0), {"tile": -8})
    assert report_viewer.tiles_again(image, zero, GroundTruthImage(image, zero, "closed-form", 0), record) is not None
