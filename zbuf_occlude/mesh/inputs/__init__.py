"""What ``generate``, ``farm`` and occlusion on the fly take: input files found, labelled and numbered.

:mod:`.kinds` (the input kinds, mesh and point set, each with its answers: the files it finds, how
one is read, its visibility method, what the card records), :mod:`.discovery` (the files of a
folder, asked of the kinds; names, splits, what was skipped), :mod:`.layouts` (ModelNet,
ShapeNetCore and other trees → labels), :mod:`.point_sets` (the clouds of a point-set file as
objects, and their frame), :mod:`.plan` (the numbered objects of a data set: :class:`~.plan.FarmObject`).
Reading a point-set file's bytes is :mod:`zbuf_occlude.io.point_sets`'s; a mesh file's,
:mod:`zbuf_occlude.mesh.load`'s; what a path says (printable text, splits, ShapeNetCore's synset),
:mod:`zbuf_occlude.mesh.paths`'.
"""
