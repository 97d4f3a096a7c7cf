"""Scene geometry as flat triangle arrays, and the analytic spheres some of those triangles stand in for."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from reference_impl.errors import SettingsError


@dataclass(frozen=True, eq=False)
class Geometry:
    """Triangles with Lambertian materials and area emission.

    Attributes
    ----------
    vertices : (V, 3) float64
        World-space positions.
    triangles : (T, 3) int
        Vertex indices. The *front* side of a triangle is the side its geometric normal
        ``cross(v1 - v0, v2 - v0)`` points to.
    material : (T,) int
        Index into ``reflectance`` and ``two_sided``.
    reflectance : (M, 3) float64
        Albedo rho of each Lambertian material, f_r = rho / pi.
    two_sided : (M,) bool
        One-sided materials reflect on the front side only (Mitsuba's ``diffuse``); two-sided ones on both.
    emission : (T, 3) float64
        Radiance Le emitted from the front side; zero for triangles that do not emit.
    light_id : (T,) int
        Which light k a triangle belongs to (all triangles of one emissive shape share an id), -1 for non-emitters.
        Ids run from 0 to N_L - 1.
    uv : (T, 3, 2) float64, optional
        The texture coordinates (u, v) at each triangle's corners, in the order of ``triangles``; a hit's are
        interpolated with its barycentrics. None: the triangles have none (0 everywhere).
    sphere_of : (T,) int64, optional
        Per triangle: -1, or the analytic sphere s of ``sphere_to_object`` whose stand-in the triangle is. A
        sphere's triangles (its icosphere, wound toward its front side) carry its material, emission and light id;
        the core hits and samples the sphere itself (:mod:`reference_impl.intersect`, :mod:`reference_impl.lights`),
        whose point x has the normal N = (x - c) / r (negated where the front side is inside, ``sphere_inward``)
        and Mitsuba's texture coordinates p = sphere_to_object[s] x, u = atan2(p_y, p_x) / (2 pi) mod 1,
        v = acos(p_z / |p|) / pi. None: no spheres.
    sphere_to_object : (S, 4, 4) float64, optional
        Per sphere: the inverse of its object-to-world matrix (the unit sphere in its own space), which may only
        rotate, scale uniformly and translate (Mitsuba's sphere).
    emission_texture : (T,) int64, optional
        Per triangle: -1 (it emits ``emission``), or the texture (of the materials' ``Materials.textures``) whose
        value at the point's texture coordinates is its radiance (Mitsuba's ``area`` emitter with a textured
        ``radiance``); ``emission`` then holds a positive stand-in (the texture's mean), which only the choice of a
        light by power reads.
    normals : (T, 3, 3) float64, optional
        The shading normals at each triangle's corners (Mitsuba's vertex normals, in the order of ``triangles``;
        normalised here), all zero for a triangle shaded flat; a hit's shading normal is their barycentric blend,
        normalised (:mod:`reference_impl.kernels.shading`). None: every triangle flat.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    material: np.ndarray
    reflectance: np.ndarray
    two_sided: np.ndarray
    emission: np.ndarray
    light_id: np.ndarray
    uv: np.ndarray | None = None
    sphere_of: np.ndarray | None = None
    sphere_to_object: np.ndarray | None = None
    emission_texture: np.ndarray | None = None
    normals: np.ndarray | None = None
    # Derived per-triangle data, filled in by __post_init__.
    normal: np.ndarray = field(init=False, repr=False)  # (T, 3) unit geometric normal
    area: np.ndarray = field(init=False, repr=False)  # (T,)
    corners: np.ndarray = field(init=False, repr=False)  # (T, 3, 3): v0, v1, v2 of each triangle
    smooth: np.ndarray = field(init=False, repr=False)  # (T,) bool: the triangle has vertex normals
    sphere_center: np.ndarray = field(init=False, repr=False)  # (S, 3) c
    sphere_radius: np.ndarray = field(init=False, repr=False)  # (S,) r
    sphere_inward: np.ndarray = field(init=False, repr=False)  # (S,) bool: the front side is the inside
    sphere_first: np.ndarray = field(init=False, repr=False)  # (S,) the first triangle of each sphere

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        triangles = np.ascontiguousarray(self.triangles, dtype=np.int64)
        n_tri = len(triangles)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise SettingsError("vertices", f"expected an array of shape (V, 3), got {vertices.shape}")
        if triangles.ndim != 2 or triangles.shape[1] != 3:
            raise SettingsError("triangles", f"expected an array of shape (T, 3), got {triangles.shape}")
        if n_tri and (triangles.min() < 0 or triangles.max() >= len(vertices)):
            raise SettingsError("triangles", "vertex index out of range")
        if not np.all(np.isfinite(vertices)):
            raise SettingsError("vertices", "expected finite coordinates")
        reflectance = np.ascontiguousarray(self.reflectance, dtype=np.float64).reshape(-1, 3)
        two_sided = np.ascontiguousarray(self.two_sided, dtype=bool).reshape(-1)
        material = np.ascontiguousarray(self.material, dtype=np.int64).reshape(-1)
        emission = np.ascontiguousarray(self.emission, dtype=np.float64).reshape(-1, 3)
        light_id = np.ascontiguousarray(self.light_id, dtype=np.int64).reshape(-1)
        for name, arr in (("material", material), ("emission", emission), ("light_id", light_id)):
            if len(arr) != n_tri:
                raise SettingsError(name, f"expected one entry per triangle ({n_tri}), got {len(arr)}")
        if len(two_sided) != len(reflectance):
            raise SettingsError("two_sided", "expected one entry per material")
        if n_tri and (material.min() < 0 or material.max() >= len(reflectance)):
            raise SettingsError("material", "material index out of range")
        if np.any(~np.isfinite(reflectance)) or np.any(reflectance < 0) or np.any(reflectance > 1):
            raise SettingsError("reflectance", "expected albedos in [0, 1]")
        if np.any(~np.isfinite(emission)) or np.any(emission < 0):
            raise SettingsError("emission", "expected finite, non-negative radiance")
        emits = np.any(emission > 0, axis=1)
        if np.any(emits != (light_id >= 0)):
            raise SettingsError("light_id", "expected an id >= 0 exactly for the triangles with emission > 0")
        if np.any(light_id >= 0):
            ids = np.unique(light_id[light_id >= 0])
            if not np.array_equal(ids, np.arange(len(ids))):
                raise SettingsError("light_id", "expected light ids 0 .. N_L - 1 without gaps")

        self._check_uv(n_tri)
        self._check_normals(n_tri)
        corners = vertices[triangles]  # (T, 3, 3)
        cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        double_area = np.linalg.norm(cross, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            normal = cross / double_area[:, None]
        normal[double_area == 0] = 0.0  # degenerate triangles: never hit, never sampled
        set_(self, "vertices", vertices)
        set_(self, "triangles", triangles)
        set_(self, "material", material)
        set_(self, "reflectance", reflectance)
        set_(self, "two_sided", two_sided)
        set_(self, "emission", emission)
        set_(self, "light_id", light_id)
        set_(self, "corners", corners)
        set_(self, "normal", normal)
        set_(self, "area", 0.5 * double_area)
        self._derive_spheres()

    def _check_uv(self, n_tri: int) -> None:
        """``uv``, ``sphere_of``, ``sphere_to_object`` and ``emission_texture`` as contiguous arrays (empty where
        None), or SettingsError."""
        set_ = object.__setattr__
        uv = np.zeros((0, 3, 2)) if self.uv is None else np.ascontiguousarray(self.uv, dtype=np.float64)
        if uv.shape not in ((0, 3, 2), (n_tri, 3, 2)) or not np.all(np.isfinite(uv)):
            raise SettingsError("uv", f"expected finite numbers in an array of shape ({n_tri}, 3, 2)")
        spheres = (np.zeros((0, 4, 4)) if self.sphere_to_object is None
                   else np.ascontiguousarray(self.sphere_to_object, dtype=np.float64))
        if spheres.ndim != 3 or spheres.shape[1:] != (4, 4) or not np.all(np.isfinite(spheres)):
            raise SettingsError("sphere_to_object", "expected finite numbers in an array of shape (S, 4, 4)")
        which = (np.zeros(0, np.int64) if self.sphere_of is None
                 else np.ascontiguousarray(self.sphere_of, dtype=np.int64).reshape(-1))
        if len(which) not in (0, n_tri) or np.any(which < -1) or np.any(which >= len(spheres)):
            raise SettingsError("sphere_of", f"expected one entry per triangle, -1 or a sphere below {len(spheres)}")
        if len(spheres) and not np.array_equal(np.unique(which[which >= 0]), np.arange(len(spheres))):
            raise SettingsError("sphere_of", "expected at least one triangle for every sphere")
        textured = (np.zeros(0, np.int64) if self.emission_texture is None
                    else np.ascontiguousarray(self.emission_texture, dtype=np.int64).reshape(-1))
        if len(textured) not in (0, n_tri) or np.any(textured < -1):
            raise SettingsError("emission_texture", "expected one entry per triangle, -1 or a texture index")
        if np.any(textured >= 0) and len(uv) == 0:
            raise SettingsError("uv", "expected the triangles' uv with emission_texture")
        set_(self, "emission_texture", textured)
        set_(self, "uv", uv)
        set_(self, "sphere_of", which)
        set_(self, "sphere_to_object", spheres)

    def _derive_spheres(self) -> None:
        """Each sphere's centre, radius, side and first triangle, from ``sphere_to_object`` and its triangles, or
        SettingsError where its placement is not a rotation, a uniform scale and a translation."""
        set_ = object.__setattr__
        n = len(self.sphere_to_object)
        center, radius = np.zeros((n, 3)), np.zeros(n)
        for s in range(n):
            with np.errstate(all="ignore"):
                to_world = np.linalg.inv(self.sphere_to_object[s])
            linear = to_world[:3, :3]
            r = abs(np.linalg.det(linear)) ** (1.0 / 3.0)
            if not (np.isfinite(r) and r > 0 and np.allclose(linear.T @ linear, r * r * np.eye(3), rtol=0,
                                                              atol=1e-9 * r * r)):
                raise SettingsError("sphere_to_object", f"sphere {s}: expected a rotation, a uniform scale and a "
                                                        "translation (Mitsuba's sphere allows nothing else)")
            center[s], radius[s] = to_world[:3, 3], r
        # Its first triangle, and its side: the area-weighted normals of its triangles against their directions from
        # the centre, summed (negative: wound toward the inside).
        tris = np.flatnonzero(self.sphere_of >= 0)
        which = self.sphere_of[tris]
        values, index = np.unique(self.sphere_of, return_index=True)
        first = index[values >= 0].astype(np.int64)
        outward = np.einsum("ij,ij->i", self.normal[tris] * self.area[tris, None],
                            self.corners[tris].mean(axis=1) - center[which])
        inward = np.bincount(which, weights=outward, minlength=n) < 0
        set_(self, "sphere_center", center)
        set_(self, "sphere_radius", radius)
        set_(self, "sphere_inward", inward)
        set_(self, "sphere_first", first)

    @property
    def num_spheres(self) -> int:
        """S, the number of analytic spheres."""
        return len(self.sphere_to_object)

    @property
    def sphere_area(self) -> np.ndarray:
        """4 pi r^2 of each sphere."""
        return 4.0 * np.pi * self.sphere_radius**2

    def _check_normals(self, n_tri: int) -> None:
        """``normals`` as a contiguous (T, 3, 3) array of unit vectors or zeros (empty where None) and ``smooth``,
        or SettingsError."""
        set_ = object.__setattr__
        if self.normals is None or np.shape(self.normals) == (0, 3, 3):
            set_(self, "normals", np.zeros((0, 3, 3)))
            set_(self, "smooth", np.zeros(0, bool))
            return
        given = np.asarray(self.normals, dtype=np.float64)  # the caller's, read only: divided into a new table
        if given.shape != (n_tri, 3, 3) or not np.all(np.isfinite(given)):
            raise SettingsError("normals", f"expected finite numbers in an array of shape ({n_tri}, 3, 3)")
        length = np.linalg.norm(given, axis=2)
        smooth = np.any(length > 0, axis=1)
        every = bool(np.all(smooth))  # a smooth mesh alone: one division, no copy, no masked copies
        if np.any(length == 0) if every else np.any(length[smooth] == 0):
            raise SettingsError("normals", "expected a non-zero normal at every corner of a smooth triangle")
        if every:
            normals = given / length[:, :, None]
        else:
            normals = np.array(given)  # a copy, in the layout np.array keeps
            normals[smooth] /= length[smooth][:, :, None]
        set_(self, "normals", normals)
        set_(self, "smooth", smooth)

    @property
    def has_shading_normals(self) -> bool:
        """Whether a triangle has vertex normals (a shading normal of its own)."""
        return bool(np.any(self.smooth))

    @property
    def textured_lights(self) -> bool:
        """Whether an area light's radiance is a texture."""
        return bool(np.any(self.emission_texture >= 0))

    @property
    def num_lights(self) -> int:
        """N_L, the number of lights (emissive shapes)."""
        return int(self.light_id.max()) + 1 if len(self.light_id) and self.light_id.max() >= 0 else 0

    @property
    def extent(self) -> float:
        """Largest coordinate magnitude of the scene's bounding box (sets ray offsets)."""
        if len(self.vertices) == 0:
            return 1.0
        return float(np.max(np.abs(self.vertices)))
