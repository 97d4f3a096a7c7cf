"""Mesh files that lie or reach out (docs/scene-format.md, "Files a scene names"): an OBJ's ``mtllib``, an MTL's
``map_Kd`` and a PLY's ``TextureFile`` are never opened (a named pipe there hung ``render`` for ever, and files
outside the scene's folder were read), the resolver meant for them stays in the scene's folder and refuses what is
not a regular file before opening it, and a PLY whose data holds fewer (or more) rows than its header declares is
refused with one line naming the file and both counts."""

from __future__ import annotations

import builtins
import io
import os
import threading
from pathlib import Path

import numpy as np
import pytest
from conftest import MINIMAL_SCENE

from harness.core.errors import HarnessError
from harness.scene import load_scene
from harness.scene.mesh_files import ConfinedResolver, ply_count_problem

TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
SCENE_WITH_MESH = MINIMAL_SCENE + '\n[[shapes]]\ntype = "mesh"\nmaterial = "white"\nfile = "{file}"\n'
WAIT = 20.0  # seconds a load may take before it counts as hung (it takes well under one)


def _scene(folder: Path, mesh: str) -> Path:
    path = folder / "scene.toml"
    path.write_text(SCENE_WITH_MESH.format(file=mesh))
    return path


def _load_in_thread(scene: Path, pipes: list[Path]):
    """load_scene(scene) in a thread; (finished, the scene or the exception). A load still blocked after WAIT
    seconds (on a named pipe of ``pipes``) is released by opening the pipes for writing, so the test ends."""
    outcome: list = []

    def load():
        try:
            outcome.append(load_scene(scene))
        except BaseException as err:  # noqa: BLE001 - reported to the test
            outcome.append(err)

    thread = threading.Thread(target=load, daemon=True)
    thread.start()
    thread.join(WAIT)
    finished = not thread.is_alive()
    if not finished:
        for pipe in pipes:
            try:
                os.close(os.open(pipe, os.O_WRONLY | os.O_NONBLOCK))  # the blocked reader's open returns, reads EOF
            except OSError:
                pass
        thread.join(WAIT)
    return finished, (outcome[0] if outcome else None)


@pytest.fixture
def opened(monkeypatch):
    """Every path opened (builtins.open, io.open, os.open) while the test runs, resolved."""
    paths: list[Path] = []
    real_open, real_os_open = builtins.open, os.open

    def recording_open(file, *args, **kwargs):
        if isinstance(file, (str, os.PathLike)):
            paths.append(Path(file).resolve())
        return real_open(file, *args, **kwargs)

    def recording_os_open(path, *args, **kwargs):
        paths.append(Path(path).resolve())
        return real_os_open(path, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", recording_open)
    monkeypatch.setattr(io, "open", recording_open)
    monkeypatch.setattr(os, "open", recording_os_open)
    return paths


# --------------------------------------------------------------------------------------------------------------------
# Item: files a mesh names (mtllib, map_Kd, TextureFile) are never opened.


@pytest.mark.parametrize("case", ["mtllib", "map_Kd", "TextureFile"])
def test_a_named_pipe_a_mesh_names_does_not_hang_the_load(tmp_path, case):
    """A fifo as the OBJ's material library, the MTL's texture or the PLY's texture: trimesh opened it and waited
    for a writer for ever."""
    pipe = tmp_path / ("pipe.mtl" if case == "mtllib" else "pipe.png")
    os.mkfifo(pipe)
    if case == "TextureFile":
        mesh = "tri.ply"
        (tmp_path / mesh).write_bytes(_ascii_ply(3, [(0, 1, 2)], comment="comment TextureFile pipe.png\n"))
    else:
        mesh = "tri.obj"
        (tmp_path / mesh).write_text(("mtllib pipe.mtl\n" if case == "mtllib" else "mtllib ok.mtl\n")
                                     + "usemtl skin\n" + "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                                     + "f 1/1 2/2 3/3\n")
        (tmp_path / "ok.mtl").write_text("newmtl skin\nKd 1 1 1\nmap_Kd pipe.png\n")
    finished, scene = _load_in_thread(_scene(tmp_path, mesh), [pipe])
    assert finished, f"loading a mesh whose {case} names a named pipe blocked for {WAIT} s"
    assert not isinstance(scene, BaseException), scene
    assert len(scene.shapes[0].mesh_triangles) == 1


def test_a_load_opens_only_the_scene_and_its_mesh(tmp_path, opened):
    """mtllib and map_Kd naming files inside the folder, beside it and by an absolute path, and a symlink to a file
    outside: the load opens the scene file and the mesh file, nothing they name (the harness ignores materials)."""
    pytest.importorskip("trimesh")  # imported before the opens are counted: its import reads files of its own
    sub, outside = tmp_path / "scene", tmp_path / "outside"
    sub.mkdir()
    outside.mkdir()
    (outside / "secret.mtl").write_text("newmtl skin\nKd 1 0 0\nmap_Kd secret.png\n")
    (outside / "secret.png").write_bytes(b"\x89PNG not really")
    (sub / "inside.mtl").write_text(f"newmtl skin\nKd 1 1 1\nmap_Kd {outside / 'secret.png'}\n")
    (sub / "link.mtl").symlink_to(outside / "secret.mtl")
    for index, library in enumerate(["inside.mtl", "../outside/secret.mtl", str(outside / "secret.mtl"),
                                     "link.mtl"]):
        mesh = sub / f"tri{index}.obj"
        mesh.write_text(f"mtllib {library}\nusemtl skin\n{TRIANGLE}")
        scene = _scene(sub, mesh.name)
        del opened[:]
        load_scene(scene)
        assert set(opened) <= {scene.resolve(), mesh.resolve()}, (library, opened)


def test_the_resolver_reads_a_file_inside_the_folder(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "skin.mtl").write_text("newmtl skin\n")
    (tmp_path / "textures").mkdir()
    (tmp_path / "textures" / "skin.png").write_bytes(b"png")
    resolver = ConfinedResolver(tmp_path, tmp_path / "meshes", "scene.toml: shapes[0].file")
    assert resolver["skin.mtl"] == b"newmtl skin\n"
    assert resolver.get("../textures/skin.png") == b"png"  # relative to the mesh's folder, inside the scene's
    assert resolver.namespaced("../textures").get("skin.png") == b"png"
    assert list(resolver.keys()) == []


def test_the_resolver_refuses_names_outside_the_folder(tmp_path):
    sub, outside = tmp_path / "scene", tmp_path / "outside"
    sub.mkdir()
    outside.mkdir()
    (outside / "secret.png").write_bytes(b"secret")
    (sub / "link.png").symlink_to(outside / "secret.png")
    resolver = ConfinedResolver(sub, sub, "scene.toml: shapes[0].file")
    for name in ("../outside/secret.png", str(outside / "secret.png"), "link.png", "/etc/passwd"):
        with pytest.raises(HarnessError, match="outside the scene's folder") as caught:
            resolver.get(name)
        assert caught.value.where == "scene.toml: shapes[0].file"
        assert "\n" not in str(caught.value)
    allowed = ConfinedResolver(sub, sub, "scene.toml: shapes[0].file", allow_outside=True)
    assert allowed.get("link.png") == b"secret"  # --allow-outside-paths lifts the folder rule only


def test_the_resolver_refuses_what_is_not_a_regular_file_before_opening_it(tmp_path, opened):
    os.mkfifo(tmp_path / "pipe.png")
    (tmp_path / "folder.png").mkdir()
    (tmp_path / "zero.png").symlink_to("/dev/zero")
    resolver = ConfinedResolver(tmp_path, tmp_path, "scene.toml: shapes[0].file", allow_outside=True)
    for name, kind in [("pipe.png", "a named pipe"), ("folder.png", "a directory"), ("zero.png", "a character device")]:
        with pytest.raises(HarnessError, match=f"not a regular file \\({kind}\\)"):
            resolver.get(name)
    with pytest.raises(HarnessError, match="no such referenced file: 'missing.png'"):
        resolver.get("missing.png")
    with pytest.raises(HarnessError, match="writes no file"):
        resolver.write("out.png", b"")
    assert opened == []


# --------------------------------------------------------------------------------------------------------------------
# Item: a PLY's element counts agree with its header.


def _strip(triangles: int) -> tuple[np.ndarray, np.ndarray]:
    """A strip of ``triangles`` triangles in the plane z = 0."""
    columns = (triangles + 1) // 2 + 1
    vertices = np.array([(i, j, 0.0) for i in range(columns) for j in (0.0, 1.0)])
    faces = []
    for i in range(columns - 1):
        a, b, c, d = 2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3
        faces += [(a, c, b), (b, c, d)]
    return vertices, np.array(faces[:triangles])


def _ascii_ply(vertex_count, faces, *, declared_faces=None, comment="", vertices=None) -> bytes:
    vertices = np.array([(i, i % 2, 0.0) for i in range(vertex_count)]) if vertices is None else vertices
    header = (f"ply\nformat ascii 1.0\n{comment}element vertex {vertex_count}\nproperty float x\nproperty float y\n"
              f"property float z\nelement face {len(faces) if declared_faces is None else declared_faces}\n"
              "property list uchar int vertex_indices\nend_header\n")
    rows = [" ".join(f"{x:g}" for x in v) for v in vertices] + [f"{len(f)} " + " ".join(map(str, f)) for f in faces]
    return (header + "\n".join(rows) + "\n").encode()


def _binary_ply(vertices, faces, *, declared_faces=None) -> bytes:
    declared = len(faces) if declared_faces is None else declared_faces
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\nproperty float x\n"
              f"property float y\nproperty float z\nelement face {declared}\n"
              "property list uchar int vertex_indices\nend_header\n").encode()
    rows = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    rows["n"], rows["i"] = 3, faces
    return header + np.asarray(vertices, "<f4").tobytes() + rows.tobytes()


def _refusal(tmp_path: Path, data: bytes) -> str:
    (tmp_path / "mesh.ply").write_bytes(data)
    scene = _scene(tmp_path, "mesh.ply")
    with pytest.raises(HarnessError) as caught:
        load_scene(scene)
    assert caught.value.where == f"{scene}: shapes[0].file"
    assert "\n" not in str(caught.value)
    assert caught.value.message.startswith("cannot read the mesh file 'mesh.ply': ")
    return caught.value.message


def test_a_truncated_ascii_ply_is_refused_naming_both_counts(tmp_path):
    """Header: 1000 faces, file: 511. It rendered silently with 511 triangles."""
    vertices, faces = _strip(1000)
    data = _ascii_ply(len(vertices), faces[:511], declared_faces=1000, vertices=vertices)
    assert "its header declares 1000 face elements but the file holds 511" in _refusal(tmp_path, data)


@pytest.mark.parametrize("writer", [_ascii_ply, _binary_ply])
def test_a_header_claiming_a_billion_faces_with_one_present_is_refused(tmp_path, writer):
    vertices, faces = _strip(1)
    data = (_ascii_ply(len(vertices), faces, declared_faces=10**9, vertices=vertices) if writer is _ascii_ply
            else _binary_ply(vertices, faces, declared_faces=10**9))
    assert "its header declares 1000000000 face elements but the file holds 1" in _refusal(tmp_path, data)


def test_a_truncated_binary_ply_is_refused_naming_both_counts(tmp_path):
    vertices, faces = _strip(1000)
    data = _binary_ply(vertices, faces)
    cut = data[:len(data) - (1000 - 511) * 13 + 5]  # 511 whole faces (13 bytes each) and 5 bytes of the 512th
    assert "its header declares 1000 face elements but the file holds 511" in _refusal(tmp_path, cut)


def test_a_ply_missing_vertices_is_refused(tmp_path):
    vertices, faces = _strip(4)
    text = _ascii_ply(len(vertices), faces, vertices=vertices).decode().splitlines(keepends=True)
    # drop the last vertex row: the faces' rows now stand where the header expects vertices
    del text[text.index("end_header\n") + len(vertices)]
    assert "declares 4 face elements but the file holds 3" in _refusal(tmp_path, "".join(text).encode())
    bare = _ascii_ply(6, [])
    bare = bare[:bare.index(b"end_header\n") + 11]
    assert "declares 6 vertex elements but the file holds 0" in _refusal(tmp_path, bare)


@pytest.mark.parametrize("extra", [b"9 9 9\n", b"\x00" * 13])
def test_data_after_the_declared_rows_is_refused(tmp_path, extra):
    vertices, faces = _strip(4)
    data = (_ascii_ply(len(vertices), faces, vertices=vertices) if extra.strip(b"\x00")
            else _binary_ply(vertices, faces)) + extra
    assert "of data after the" in _refusal(tmp_path, data)


def test_binary_lists_of_differing_lengths_are_refused():
    """trimesh reads every list of a binary PLY as long as the first row's; a row that differs is refused."""
    vertices, faces = _strip(4)
    data = bytearray(_binary_ply(vertices, faces))
    data[data.index(b"end_header\n") + 11 + len(vertices) * 12 + 2 * 13] = 4  # the third face's list length
    assert ply_count_problem(bytes(data)) == ("face element 2 has a list of 4 entries, the first 3; a binary PLY's "
                                              "lists must all be as long as in its first row")


@pytest.mark.parametrize("writer", ["ascii", "binary", "quads"])
def test_ply_files_whose_counts_agree_load(tmp_path, writer):
    vertices, faces = _strip(1000)
    if writer == "quads":
        data = _ascii_ply(4, [(0, 1, 3, 2)], vertices=np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0.0)]))
    else:
        data = (_ascii_ply(len(vertices), faces, vertices=vertices) if writer == "ascii"
                else _binary_ply(vertices, faces))
    assert ply_count_problem(data) is None
    (tmp_path / "mesh.ply").write_bytes(data)
    shape = load_scene(_scene(tmp_path, "mesh.ply")).shapes[0]
    assert len(shape.mesh_triangles) == (2 if writer == "quads" else 1000)
    if writer != "quads":
        np.testing.assert_array_equal(shape.mesh_triangles, faces)


def test_ply_files_trimesh_writes_pass_the_count_check():
    trimesh = pytest.importorskip("trimesh")
    mesh = trimesh.creation.icosphere(2)
    for encoding in ("ascii", "binary"):
        assert ply_count_problem(mesh.export(file_type="ply", encoding=encoding)) is None
