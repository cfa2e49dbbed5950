"""The ``sapiv-distortion`` replication: SAPIV under radial distortion and spherical aberration
(seed paper 002).

``model``: the paper's own image model; ``study``: ``STUDY``, its rows, sweeps and report; the
paper's set-up and our readings of it are in this folder's README.md."""
