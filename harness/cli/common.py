"""What the commands share: the exit codes, the parser class, the shared options (each declared once, as argparse
parent parsers), the progress bar, the ``--allow-outside-paths`` context and the command runner that turns a user
error into one line on stderr."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import select
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

from tqdm import tqdm

from harness.core import options
from harness.core.errors import ALLOW_OUTSIDE_ENV, HarnessError
from harness.core.options import Parser  # the shell's parser class (common.Parser), its parents' too
from harness.core.limits import MAX_FILM_SIDE, check_render_cost, film_problem

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2
# A closed stdout (``harness ... | head``): what a shell reports for a command killed by SIGPIPE, 128 + 13. Python
# ignores SIGPIPE, so the harness sees BrokenPipeError instead, and exits quietly with this code.
EXIT_BROKEN_PIPE = 141
EXIT_INTERRUPTED = 130

#: The canonical scenes of a checkout (``scenes/NAME.toml``), which commands also take by NAME.
SCENES = Path(__file__).resolve().parents[2] / "scenes"
SCENE_HELP = ("scene file (TOML, see docs/scene-format.md), or a scene NAME as a suite's scene names it: "
              "scenes/NAME.toml here or in this checkout, e.g. furnace")
SUITE_HELP = "suite file (TOML, see docs/suites.md)"



# ---- the shared options ------------------------------------------------------------------------------------------

#: The section of a command's help that lists the shared options (argparse merges the parents' groups of one title).
SHARED_TITLE = "common options"


def _parent(flag: str, **kwargs) -> argparse.ArgumentParser:
    parent = Parser(add_help=False)
    parent.add_argument_group(SHARED_TITLE).add_argument(flag, **kwargs)
    return parent


class Common:
    """The options several commands share, each declared here once; every method returns a parent parser for
    ``sub.add_parser(NAME, parents=[...])``. A command declares its own options on :meth:`own` and gives it first
    (argparse lists the parents' options in order, in the usage line, the help and the "the following arguments
    are required" message), then the shared ones in the order of the methods below, so that every command lists
    them alike."""

    @staticmethod
    def own() -> argparse.ArgumentParser:
        """An empty parent parser for the command's own arguments (and its ``set_defaults``)."""
        return Parser(add_help=False)

    @staticmethod
    def film() -> argparse.ArgumentParser:
        """``--film WxH``: the scene rendered (or exported) at another resolution, as a suite case's ``film`` does
        (:func:`with_film`); listed with the command's own options, right after :meth:`own`."""
        parent = Parser(add_help=False)
        parent.add_argument("--film", type=options.film_size, metavar="WxH",
                            help="the scene's film replaced by WIDTHxHEIGHT pixels, e.g. 32x32 (its filter kept), as "
                            "a suite case's film does (default: the scene's)")
        return parent

    @staticmethod
    def out(help: str, *, required: bool = False, metavar: str | None = None, file: bool = False
            ) -> argparse.ArgumentParser:
        """``--out``: where the command writes, a folder (or a ``file``); ``help`` says what and its default. An
        empty value is refused (``options.out_folder`` / ``out_file``), not read as the default."""
        kind = options.out_file if file else options.out_folder
        return _parent("--out", required=required, metavar=metavar, type=kind, help=help)

    @staticmethod
    def json(help: str = "print the result as one JSON object on stdout") -> argparse.ArgumentParser:
        """``--json``: the result as JSON on stdout (``help``: what the object holds)."""
        return _parent("--json", action="store_true", help=help)

    @staticmethod
    def quiet() -> argparse.ArgumentParser:
        """``--quiet``: no progress bar or progress lines."""
        return _parent("--quiet", action="store_true", help="no progress bar or progress lines on stderr")

    @staticmethod
    def cache_dir() -> argparse.ArgumentParser:
        """``--cache-dir``: the ground-truth cache (harness/renderers/groundtruth.py), and the results cache of
        ``harness run`` in its ``results/`` (harness/running/result_cache.py)."""
        return _parent("--cache-dir",
                       help="ground-truth cache folder, and harness run's results cache in its results/ (default: "
                       "$HARNESS_CACHE_DIR or the user cache dir)")

    @staticmethod
    def mitsuba_variant() -> argparse.ArgumentParser:
        """``--mitsuba-variant``: the variant of every Mitsuba render (ground truths, ``--renderer mitsuba``)."""
        return _parent("--mitsuba-variant",
                       help="Mitsuba variant of every Mitsuba render, e.g. scalar_rgb (default: the best that works)")

    @staticmethod
    def allow_outside_paths() -> argparse.ArgumentParser:
        """``--allow-outside-paths``: for the commands that load scene files, and so follow their mesh paths."""
        return _parent("--allow-outside-paths", action="store_true",
                       help="let scenes name mesh files outside their own folder (default: refused)")


# ---- helpers of the command bodies ---------------------------------------------------------------------------


def progress_bar(args: argparse.Namespace, description: str, unit: str, *, total: int = 0,
                 unit_scale: bool = False, leave: bool = False) -> tqdm | None:
    """A tqdm bar on stderr, or None with ``--quiet`` or when stderr is not a terminal."""
    if args.quiet or not sys.stderr.isatty():
        return None
    return tqdm(total=total, desc=description, unit=unit, unit_scale=unit_scale, file=sys.stderr, leave=leave)


def path_progress(args: argparse.Namespace, description: str) -> tuple[tqdm | None, Callable[[int, int], None] | None]:
    """A bar counting paths and the ``progress(done, total)`` callback a render feeds it (both None when quiet)."""
    bar = progress_bar(args, description, "path", unit_scale=True)
    if bar is None:
        return None, None

    def progress(done: int, total: int) -> None:
        if bar.total != total:
            bar.total = total
        bar.update(done - bar.n)

    return bar, progress


def exr_out_path(text: str) -> Path:
    """``--out FILE.exr`` checked before any work: the name ends in ``.exr`` and its folder exists and is writable
    (HarnessError at ``--out``)."""
    out = Path(text)
    if out.suffix.lower() != ".exr":
        raise HarnessError("--out", f"expected a file name ending in .exr, got {text!r}")
    if not out.parent.is_dir():
        raise HarnessError("--out", f"folder {str(out.parent)!r} does not exist")
    if not os.access(out.parent, os.W_OK):
        raise HarnessError("--out", f"folder {str(out.parent)!r} is not writable")
    return out


def film_pixels(film: str | None) -> tuple[int, int] | None:
    """``--film``'s WIDTHxHEIGHT as (width, height), None without ``--film``; a film beyond the scene format's
    limits is a HarnessError at ``--film``."""
    if not film:
        return None
    width, _, height = film.lower().partition("x")
    width, height = int(width), int(height)
    if max(width, height) > MAX_FILM_SIDE:
        raise HarnessError("--film", f"expected at most {MAX_FILM_SIDE} pixels per side, got {film!r}")
    problem = film_problem(width, height)
    if problem:
        raise HarnessError("--film", problem)
    return width, height


def with_film(scene, film: str | None):
    """``scene`` with its film replaced by ``--film``'s WIDTHxHEIGHT (:func:`film_pixels`; its filter kept); as it
    is without ``--film``."""
    pixels = film_pixels(film)
    if pixels is None:
        return scene
    return dataclasses.replace(scene, film=dataclasses.replace(scene.film, width=pixels[0], height=pixels[1]))


def check_cost(scene, spp: int | None, option: str, *, seconds: float | None = None) -> None:
    """Refuse a render of ``scene`` at ``spp`` (or for ``seconds``: a time budget of at most 24 h) whose memory or
    time estimate is absurd (harness/core/limits.py)."""
    check_render_cost(scene.film.width, scene.film.height, spp, film_where=f"{scene.path}: film",
                      spp_where=option, film_keys=f"film.width / film.height in {scene.path}", spp_name=option,
                      seconds=seconds, envmap=scene.envmap_size, envmap_where=scene.envmap_key)


@contextlib.contextmanager
def outside_paths(args: argparse.Namespace) -> Iterator[None]:
    """With ``--allow-outside-paths``: set ``$HARNESS_ALLOW_OUTSIDE_PATHS`` (read by load_scene, inherited by worker
    processes) for the command's duration, then restore it."""
    if not getattr(args, "allow_outside_paths", False):
        yield
        return
    saved = os.environ.get(ALLOW_OUTSIDE_ENV)
    os.environ[ALLOW_OUTSIDE_ENV] = "1"
    try:
        yield
    finally:
        if saved is None:
            os.environ.pop(ALLOW_OUTSIDE_ENV, None)
        else:
            os.environ[ALLOW_OUTSIDE_ENV] = saved


# ---- running a command ---------------------------------------------------------------------------------------


# What str.splitlines() breaks a line at, written as escapes: an error quoting the user's text (an argument with a
# newline, a file name with U+2028) stays one line.
_LINE_BREAKS = {ord(c): c.encode("unicode_escape").decode("ascii") for c in "\n\r\v\f\x1c\x1d\x1e\x85\u2028\u2029"}


def one_line(text: str) -> str:
    """``text`` with every line break escaped (``\\n``, ``\\u2028``, ...)."""
    return text.translate(_LINE_BREAKS)


def dispatch(build_parser: Callable[[], argparse.ArgumentParser], argv: list[str] | None) -> int:
    """Parse ``argv`` and run the command's ``run(args)``; a user error is one line on stderr and exit code 2."""
    try:
        args = build_parser().parse_args(argv)
        with outside_paths(args):
            return args.func(args)
    except HarnessError as err:
        print(f"harness: error: {one_line(str(err))}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("harness: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def _closed(stream) -> bool:
    """Whether ``stream`` is a pipe (or socket) whose reader has gone: poll() reports an error on it."""
    try:
        poller = select.poll()
        poller.register(stream.fileno(), select.POLLOUT)
        return any(events & (select.POLLERR | select.POLLHUP) for _, events in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # no poll() (Windows) or no file descriptor: assume closed
        return True


def _discard(stream) -> None:
    """Point ``stream``'s file descriptor at /dev/null, so that what is still buffered (flushed again at
    interpreter shutdown) goes nowhere instead of raising BrokenPipeError there."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stream.fileno())
        os.close(devnull)
    except (AttributeError, OSError, ValueError):
        pass


def quiet_broken_pipe(error: BrokenPipeError) -> int:
    """After a BrokenPipeError: :data:`EXIT_BROKEN_PIPE`, the closed stdout or stderr pointed at /dev/null; an
    error from some other pipe (a worker's) is raised again."""
    broken = [stream for stream in (sys.stdout, sys.stderr) if _closed(stream)]
    if not broken:  # not ours: some other pipe broke
        raise error
    for stream in broken:
        _discard(stream)
    return EXIT_BROKEN_PIPE
