"""The ``drop-fragments`` replication: plenoptic imaging against digital in-line holography of
drop fragments (seed paper 003).

``study``: ``STUDY``, its rows, sweeps and report (its image models are mitpiv's own:
:mod:`mitpiv.render.backlit`, :mod:`mitpiv.holography`); the paper's set-up and our readings
of it are in this folder's README.md."""
