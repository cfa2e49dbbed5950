"""mitpiv's tracking study: Shake-The-Box (mitpiv's and OpenLPT's) and tomographic PIV against
particle density, from a finished ``mitpiv sweep`` (``study``: ``write_tracking_study``)."""
