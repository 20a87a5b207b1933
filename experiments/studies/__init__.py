"""trackenv_studies: the studies built on the library, installed apart from it (the folder ``experiments/studies``).

* :mod:`trackenv_studies.validation` — the track model against closed forms and the paper's figures
  (``trackenv validate``);
* :mod:`trackenv_studies.paper` — the paper's section 4 reproduced (``trackenv paper``);
* :mod:`trackenv_studies.bench` — how fast the physics and the envs run (``trackenv bench``);
* :mod:`trackenv_studies.calibration` — the line problem against published figures (``trackenv calibrate``).

The library ``trackenv`` never imports them (a test keeps it so); the command line and ``experiments/`` do.
"""
