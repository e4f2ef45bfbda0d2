"""The recording layout (docs/format.md): format name and version, sensor groups, and what each group must hold.

One HDF5 file per sequence × lux::

    /             attrs: format, format_version, width, height, duration_s, lux, scene, sequence, spec, …
    /gt           t [n] s, flux [n,H,W] ph s⁻¹ m⁻², depth [n,H,W] m (optional); with geometry passes also
                  instance [n,H,W] uint16, flow [n,H,W,2] px, flow_valid [n,H,W] uint8, velocity [n,H,W,2] px s⁻¹,
                  camera_to_world [n,4,4], object_to_world [n,K,4,4] (when objects move)
    /camera       attrs focal_px, cx_px, cy_px, x_fov_deg, y_fov_deg, …; K [3,3] px (with geometry passes)
    /poses        t [k] s, camera_to_world [k,4,4] (optional)
    /spad         bits [n,H,ceil(W/8)] uint8 (little bit order), t_start [n] s, dcr_cps [H,W]
    /frames       dn [k,H,W] uint16, t_start [k] s, t_end [k] s
    /events       t [m] int64 µs, x, y [m] uint16, p [m] uint8 (1 ON / 0 OFF), label [m] uint8 (optional),
                  ms_to_idx [ms] (index of the first event of each millisecond)
"""

FORMAT = "simspad-recording"
FORMAT_VERSION = 1
#: The sensor kinds, in the order their groups are listed; every layer takes the names from here.
SENSOR_KINDS = ("spad", "frames", "events")

#: Root attributes every recording has.
REQUIRED_ROOT_ATTRS = ("width", "height", "duration_s", "lux")
#: Datasets a group must hold when the group is present.
REQUIRED_DATASETS = {
    "gt": ("gt/t", "gt/flux"),
    "spad": ("spad/bits", "spad/t_start", "spad/dcr_cps"),
    "frames": ("frames/dn", "frames/t_start", "frames/t_end"),
    "events": ("events/t", "events/x", "events/y", "events/p", "events/ms_to_idx"),
}
#: Datasets a recording may hold besides the required ones (the geometry of a render with geometry passes:
#: docs/format.md, section 3), by group; when one of a group's geometry datasets is there, all but
#: ``gt/object_to_world`` (written only when objects move) are.
OPTIONAL_DATASETS = {
    "gt": ("gt/depth", "gt/instance", "gt/flow", "gt/flow_valid", "gt/velocity", "gt/camera_to_world",
           "gt/object_to_world"),
    "camera": ("camera/K",),
    "poses": ("poses/t", "poses/camera_to_world"),
}
#: Attributes a sensor group must carry when the group is present.
REQUIRED_GROUP_ATTRS = {
    "spad": ("bin_s", "gate_s", "pixel_pitch_m", "fill_factor", "qe"),
    "frames": ("gain_dn_per_e", "black_level_dn", "bit_depth", "qe", "pixel_pitch_m", "fill_factor"),
    "events": ("threshold_on", "threshold_off"),
}
