"""A face to see motion on (Cao et al. 2005, §7): mesh deformation, rendering, glTF.

* :mod:`.mesh` -- face meshes, marker maps and the RBF scattered-data deformer;
* :mod:`.animation` -- point motion carried onto the mesh (:func:`~.animation.animate`);
* :mod:`.arkit` -- ARKit blendshape curves (iPhone captures) on the canonical mesh;
* :mod:`.render` -- MP4, GIF, PNG or OBJ frames of a face animation or of curves;
* :mod:`.gltf` -- the animation as glTF 2.0 (.glb) with morph targets (ARKit-named for
  ARKit curves).

Imports: ``db``, ``ingest`` and :mod:`animegraph.motion`.
"""
