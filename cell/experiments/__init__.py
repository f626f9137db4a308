"""The experiments run on the twin, apart from the cell as a product (``cell/``).

Why a package of their own: the production application -- configuration, assembly, the tick
loop, the journal, the hardware backend and their commands -- must stay small and reviewable, and
must not depend on what only measures or trains: randomized pivot trials (``cell pivot``) and
their parallel sweep on Ray (``cell sweep``), the regrasp baseline (``cell compare``), the fault
soak (``cell soak``), bin perception scoring and training (``cell perceive``,
``cell train-perception``), the hand-eye calibration in the twin (``cell calibrate``), and the
figures and statistics they report. Every one of them is reached through the same ``cell`` command
line; this package only moves where their code lives.
"""
