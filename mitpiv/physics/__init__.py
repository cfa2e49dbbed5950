"""Pure NumPy physics: no renderer is imported here.

Modules: ``distortion`` (Brown-Conrady), ``camera`` (pinhole camera model and camera
placement), ``sheet`` (laser-sheet profiles), ``seeding``, ``flows``, ``advection``,
``mie`` (Mie scattering of spheres), ``psf`` (Fourier-optics PSF with Zernike
aberrations), ``targets`` (calibration dot grids and checkerboards).
"""
