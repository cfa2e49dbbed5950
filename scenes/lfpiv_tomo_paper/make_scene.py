"""Regenerate scenes/lfpiv_tomo_paper/scene.xml: Shi et al.'s simultaneous LF-PIV / Tomo-PIV
experiment (seed paper 001, section 3, Table 4) as a simulated rig.

- One light-field camera ``plen`` on the +z axis (sensor parallel to the jet): 5.5 um pixels
  (the in-house camera built on a 29 Mpx Imperx B6640), Micro-NIKKOR 200 mm at 0.0058 mm per
  pixel (magnification 5.5 / 5.8), hexagonal MLA of 77 um lenslets (PMR 14, f-number matched:
  the lens aperture is chosen so its image-side f-number equals the lenslets'), the sensor
  ``$lf_width x $lf_height`` pixels (6600 x 4400 in the paper; a centred crop is the same
  camera with fewer pixels, its MLA filling the crop). ``$lf_centre_y_mm`` moves the camera
  along y: a crop of the sensor centred that far off the axis, to within the chief rays'
  obliquity (10 mm at 411 mm: 1.4 deg, neglected).
- Four tomographic cameras ``t0..t3`` in a cross around it (azimuth 0 / 90 / 180 / 270 deg,
  25 deg off the z axis, each with its 480 px side along the jet), 480 x 320 px of 7.4 um (the 4 Mpx Imperx B2014's pitch,
  the paper's simulated Tomo camera, section 2.2), Micro-NIKKOR 85 mm at 0.079 mm per pixel
  (object distance f (1 + 1/M) = 992.4 mm), f/11 thin lens Scheimpflug-focused on the sheet
  mid-plane z = 0.
- A 10 mm top-hat laser sheet at 532 nm along +y (across the jet) with normal +z; 20 um
  polyamide particles (n = 1.5) in water (1.333), Lorenz-Mie scattering.

What the paper does not give and we chose: the cross's half-angle (25 deg), the Tomo f-number
(f/11: diffraction spot 2.44 lambda N (1 + M) = 15.6 um = 2.1 px, depth of field well over the
10 mm sheet), the laser direction, and f-number matching of the light-field camera (the
Micro-NIKKOR 200 mm's f/4 is f/7.8 working at this magnification, half the lenslets' f/4
cone: set ``lf_aperture_mm`` to 200 / 4 = 50 for that lens wide open).

    python scenes/lfpiv_tomo_paper/make_scene.py
"""

import math
from pathlib import Path

import numpy as np

from mitpiv.physics.camera import place_camera, scheimpflug
from mitpiv.physics.sphere_cameras import distorted_pinhole_sensors_xml

# light-field camera (Table 4)
LF_PIXEL_UM = 5.5
LF_MM_PER_PX = 0.0058
LF_FOCAL_MM = 200.0
LF_M = LF_PIXEL_UM * 1e-3 / LF_MM_PER_PX  # 0.948
LF_OBJECT_MM = LF_FOCAL_MM * (1 + 1 / LF_M)  # 410.9 mm
LF_IMAGE_MM = LF_FOCAL_MM * (1 + LF_M)  # 389.7 mm
MLA_F_NUMBER = 4.0  # the in-house MLA: 77 um lenslets, 308 um focal length (Shi et al. 2016)
LF_APERTURE_MM = LF_IMAGE_MM / MLA_F_NUMBER  # image-side f/4: f-number matched
MLA_PITCH_UM = 14 * LF_PIXEL_UM  # PMR 14: 77 um
# tomographic cameras (Table 4, section 2.2)
T_PIXEL_UM = 7.4
T_MM_PER_PX = 0.079
T_FOCAL_MM = 85.0
T_M = T_PIXEL_UM * 1e-3 / T_MM_PER_PX  # 0.0937
T_OBJECT_MM = T_FOCAL_MM * (1 + 1 / T_M)  # 992.4 mm
T_IMAGE_MM = T_FOCAL_MM * (1 + T_M)  # 93.0 mm: the pinhole-to-sensor distance of the mapping
T_F_NUMBER = 11.0
# the plugin's aperture is focal_length_mm / (2 f_number) with focal_length_mm the pinhole
# (image) distance: the f-number that gives the 85 mm lens's f/11 aperture
T_PLUGIN_F_NUMBER = T_IMAGE_MM / (T_FOCAL_MM / T_F_NUMBER)
CROSS_DEG = 25.0

cams = []
for az in (0.0, 90.0, 180.0, 270.0):
    rot, pos = place_camera(target_mm=(0.0, 0.0, 0.0), azimuth_deg=az, elevation_deg=90.0 - CROSS_DEG,
                            distance_mm=T_OBJECT_MM)
    s = scheimpflug(rot, pos, focal_length_mm=T_FOCAL_MM, plane_point_mm=(0.0, 0.0, 0.0), plane_normal=(0.0, 0.0, 1.0))
    cams.append({"azimuth_deg": az, "elevation_deg": 90.0 - CROSS_DEG, "rotation": rot, "position_mm": pos,
                 "scheimpflug": s})
psf = (f'<string name="psf" value="fft"/>\n<float name="psf_f_number" value="{T_F_NUMBER:g}"/>\n'
       f'<float name="psf_magnification" value="{T_M:.6g}"/>\n<float name="psf_energy_tolerance" value="0.005"/>')
tomo = distorted_pinhole_sensors_xml(cams, distance_mm=T_OBJECT_MM, focal_length_mm=T_IMAGE_MM,
                                     pixel_pitch_um=T_PIXEL_UM, f_number=T_PLUGIN_F_NUMBER, film_id="tomofilm",
                                     ids=[f"t{i}" for i in range(4)], extra_xml=psf)
# every camera's 480 px side along the jet (x, the volume's 38 mm): a look-at pose with image
# "up" along y instead of the sphere placement's (which turns the cameras at azimuth 0 / 180 by
# 90 deg, their 320 px side along x)
blocks = []
for cam, block in zip(cams, tomo.rstrip().split("\n\n"), strict=True):
    keep = [ln for ln in block.splitlines() if not any(f'name="{k}"' in ln for k in (
        "target", "laser_direction", "sheet_normal", "azimuth_deg", "elevation_deg", "distance_mm"))]
    o = ", ".join(f"{v:.10g}" for v in cam["position_mm"])
    keep.insert(1, f'        <transform name="to_world"><lookat origin="{o}" target="0, 0, 0" up="0, 1, 0"/></transform>')
    blocks.append("\n".join(keep))
tomo = "\n\n".join(blocks) + "\n"
tilts = ", ".join(f"{c['scheimpflug']['object_tilt_deg']:.1f}" for c in cams)

xml = f"""<scene version="3.0.0">
    <!-- lfpiv_tomo_paper: Shi et al.'s simultaneous LF-PIV / Tomo-PIV jet experiment (seed paper
         001, section 3, Table 4). Generated by make_scene.py (its docstring lists our readings).
         Units: mm. Volume 38 x 26 x 10 mm about the origin, jet along +x.
         plen: {LF_PIXEL_UM:g} um pixels, {LF_FOCAL_MM:g} mm lens at M = {LF_M:.4f} ({LF_MM_PER_PX} mm/px), object
         distance {LF_OBJECT_MM:.1f} mm, aperture {LF_APERTURE_MM:.1f} mm (image-side f/{MLA_F_NUMBER:g}, matched),
         hexagonal {MLA_PITCH_UM:g} um lenslets (PMR 14); sensor $lf_width x $lf_height px (6600 x 4400 in
         the paper), centred on y = $lf_centre_y_mm (a crop of the whole sensor). t0..t3: {T_PIXEL_UM:g} um pixels, {T_FOCAL_MM:g} mm lens at M = {T_M:.4f}
         ({T_MM_PER_PX} mm/px), {T_OBJECT_MM:.1f} mm away, {CROSS_DEG:g} deg off the z axis in a cross, f/{T_F_NUMBER:g},
         Scheimpflug on z = 0 (object-plane tilts {tilts} deg). -->
    <default name="frame" value="0"/>
    <default name="lf_width" value="660"/>
    <default name="lf_height" value="440"/>
    <default name="lf_aperture_mm" value="{LF_APERTURE_MM:.4f}"/>
    <default name="lf_centre_y_mm" value="0"/>
    <default name="rays_per_particle" value="20000"/>

    <integrator type="particle_tracer">
        <integer name="rays_per_particle" value="$rays_per_particle"/>
    </integrator>

    <film type="hdrfilm" id="plenfilm">
        <integer name="width" value="$lf_width"/>
        <integer name="height" value="$lf_height"/>
        <string name="pixel_format" value="luminance"/>
        <rfilter type="box"/>
    </film>
    <film type="hdrfilm" id="tomofilm">
        <integer name="width" value="480"/>
        <integer name="height" value="320"/>
        <string name="pixel_format" value="luminance"/>
        <rfilter type="catmullrom"/>
    </film>

    <emitter type="laser_sheet" id="laser">
        <point name="origin" value="0, -100, 0"/>
        <vector name="direction" value="0, 1, 0"/>
        <vector name="normal" value="0, 0, 1"/>
        <float name="thickness" value="10"/>
        <string name="profile" value="tophat"/>
        <float name="irradiance" value="1"/>
        <float name="wavelength_nm" value="532"/>
    </emitter>

    <shape type="ellipsoidsmesh" id="particles">
        <string name="filename" value="particles_$frame.ply"/>
        <float name="extent" value="1"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="tracer_particles">
            <ref name="sheet" id="laser"/>
            <phase type="mie">
                <float name="index" value="1.5"/>
                <float name="medium_index" value="1.333"/>
            </phase>
        </emitter>
    </shape>

    <sensor type="plenoptic" id="plen">
        <point name="target" value="0, $lf_centre_y_mm, 0"/>
        <float name="azimuth_deg" value="0"/>
        <float name="elevation_deg" value="90"/>
        <float name="distance_mm" value="{LF_OBJECT_MM:.6g}"/>
        <float name="focal_length_mm" value="{LF_FOCAL_MM:g}"/>
        <float name="aperture_diameter_mm" value="$lf_aperture_mm"/>
        <float name="focus_distance_mm" value="{LF_OBJECT_MM:.6g}"/>
        <float name="pixel_pitch_um" value="{LF_PIXEL_UM:g}"/>
        <float name="mla_pitch_um" value="{MLA_PITCH_UM:g}"/>
        <float name="mla_focal_length_um" value="{MLA_PITCH_UM * MLA_F_NUMBER:g}"/>
        <string name="mla_layout" value="hex"/>
        <ref id="plenfilm"/>
    </sensor>

{tomo}</scene>
"""
assert math.isclose(T_OBJECT_MM * T_PIXEL_UM * 1e-3 / T_IMAGE_MM, T_MM_PER_PX, rel_tol=1e-9)
assert np.isclose(LF_OBJECT_MM * LF_PIXEL_UM * 1e-3 / LF_IMAGE_MM, LF_MM_PER_PX)
Path(__file__).with_name("scene.xml").write_text(xml)
