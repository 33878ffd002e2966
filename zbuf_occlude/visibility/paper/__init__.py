"""The paper's object-space HSR methods (Sryamkin et al. 2023, §3.2–3.3, Eq. 1–10).

:mod:`.vertex` (a point is visible when no face hides the segment to the camera, vertex test),
:mod:`.object_space` (the exact segment–face test, Eq. 1–10), :mod:`.pruning` (faces pruned by
their bounding boxes before the test), :mod:`.occupancy` (occupancy-grid HSR), :mod:`.face_scan`
(the exact test scanned over faces with numba).  Each registers itself in
:mod:`zbuf_occlude.visibility.registry` when imported; the registry imports them at the first lookup.
"""
