"""The ``channel-tomo`` replication: tomographic PIV of a turbulent channel at Re_tau 934 (seed
paper 004).

``model``: the paper's own image model; ``study``: ``STUDY``, its rows, sweeps and report; the
paper's set-up and our readings of it are in this folder's README.md."""
