"""The paper's tables and figures and the runs that go beyond them.

:mod:`.compare` (image space vs object space HSR, Tables 1A/1B), :mod:`.elevation_profile`
(agreement with the oracle vs elevation), :mod:`.table3` (classifiers vs elevation and
augmentation, Table 3; :mod:`.paper` holds the paper's numbers), :mod:`.sim2real` (trained on
meshes, tested on real scans), :mod:`.realism` (simulated scans against real ones),
:mod:`.contact_sheet` (a picture of a few samples per class of a data set or a folder of scans).
"""
