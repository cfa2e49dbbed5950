"""Pure NumPy physics: no renderer is imported here.

Modules: ``distortion`` (Brown-Conrady), ``camera`` (the camera contract
:class:`~mitpiv.physics.camera.Camera`, the pinhole / thin-lens camera model and camera
placement), ``plenoptic`` (plenoptic 1.0 camera geometry and design calculators, the same
contract), ``sheet`` (laser-sheet profiles), ``seeding`` (particles in a box, and counts
for a target image density in any camera), ``flows``, ``advection``, ``mie`` (Mie
scattering of spheres), ``psf`` (Fourier-optics PSF with Zernike aberrations), ``targets``
(calibration dot grids and checkerboards).
"""
