"""The ``lfpiv-vs-tomo`` replication: single-camera light-field PIV against tomographic PIV
(seed paper 001).

``model``: the paper's own image model; ``study``: ``STUDY``, its rows, sweeps and report; the
paper's set-up and our readings of it are in this folder's README.md."""
