"""The ``multi-plenoptic`` replication: one to four plenoptic cameras against MART (seed paper
000).

``model``: the paper's own image model; ``study``: ``STUDY``, its rows, sweeps and report; the
paper's set-up and our readings of it are in this folder's README.md."""
