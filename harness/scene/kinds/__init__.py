"""One registry per scene concept: each type of a concept is one entry holding its TOML keys and their reading, its
row in the core (:mod:`reference_impl`), its Mitsuba plugin (in :mod:`harness.renderers.mitsuba_spec`'s form) and its
scene.json entry (:mod:`harness.renderers.scene_json`).

* :mod:`harness.scene.kinds.materials`: ``[materials.NAME]``, :data:`~harness.scene.kinds.materials.MATERIALS`;
* :mod:`harness.scene.kinds.emitters`: ``[[emitters]]``, :data:`~harness.scene.kinds.emitters.EMITTERS`;
* :mod:`harness.scene.kinds.media`: ``[media.NAME]``, :data:`~harness.scene.kinds.media.MEDIA` (their core rows:
  :func:`harness.scene.media_arrays.media_arrays`, with the shapes' medium transitions per triangle);
* :mod:`harness.scene.kinds.shapes`: ``[[shapes]]``, :data:`~harness.scene.kinds.shapes.SHAPES` (their triangles and
  placement instead of a core row: :func:`harness.scene.triangulate.triangulate` joins them);
* :mod:`harness.scene.kinds.mitsuba_values`: the neutral values a Mitsuba plugin dict holds (transforms, points,
  files), written by each form (``mi.load_dict``, XML) its own way.

Code that handles a scene's materials, emitters or shapes looks the entry up by the type name (``MATERIALS[m.type]``)
instead of testing the name. The scene model (:mod:`harness.scene.model`) names the types; each registry holds them in
that order.
"""
