"""Find a RealSense device, choose its depth and colour streams, and set its depth options.

Every function takes the pyrealsense2 module as `rs` (see capture.realsense.record.rs_module).
"""

from __future__ import annotations

from typing import Any

from capture.errors import CameraError
from capture.realsense.camera import TO_RGB
from capture.realsense.session import RecordConfig, Streams
from capture.recording.frames import Extrinsics, Intrinsics

_DEVICE_INFO = {"name": "name", "serial_number": "serial_number",
                "firmware_version": "firmware_version", "usb_type": "usb_type_descriptor",
                "product_line": "product_line"}  # fmt: skip


def intrinsics_of(rs: Any, profile: Any) -> Intrinsics:
    """Return the Intrinsics of a video stream profile, with realsense-ros's distortion naming."""
    k = profile.as_video_stream_profile().get_intrinsics()
    fisheye = k.model == rs.distortion.kannala_brandt4
    coeffs = tuple(float(c) for c in k.coeffs)[: 4 if fisheye else 5]
    return Intrinsics(
        width=int(k.width),
        height=int(k.height),
        fx=float(k.fx),
        fy=float(k.fy),
        cx=float(k.ppx),
        cy=float(k.ppy),
        # As realsense-ros: Brown-Conrady (and its inverse, which D435 colour reports, always
        # with zero coefficients) are plumb_bob k1 k2 p1 p2 k3; Kannala-Brandt is equidistant.
        distortion_model="equidistant" if fisheye else "plumb_bob",
        coeffs=coeffs,
    )


def find_device(rs: Any, serial: str | None) -> Any:
    """Return the connected RealSense device (with the serial number, if given)."""
    devices = list(rs.context().query_devices())
    serials = [d.get_info(rs.camera_info.serial_number) for d in devices]
    if not devices:
        raise CameraError("no RealSense camera found; connect a D435 to a USB 3 port")
    if serial is None:
        return devices[0]
    if serial not in serials:
        raise CameraError(f"no RealSense camera with serial {serial}; found: {', '.join(serials)}")
    return devices[serials.index(serial)]


def _mode(p: Any) -> str:
    return f"{p.width()}x{p.height()}@{p.fps()} {p.format().name}"


def select_streams(rs: Any, device: Any, config: RecordConfig | None) -> Streams:
    """Pick the depth (z16) and colour streams; `config` None takes the first of each (files)."""
    found: dict[str, list[tuple[int, Any]]] = {"depth": [], "color": []}
    sensors = list(device.query_sensors())
    for i, sensor in enumerate(sensors):
        for p in sensor.get_stream_profiles():
            if not p.is_video_stream_profile():
                continue
            vp = p.as_video_stream_profile()
            if vp.stream_type() == rs.stream.depth and vp.format() == rs.format.z16:
                found["depth"].append((i, vp))
            elif vp.stream_type() == rs.stream.color and vp.format().name in TO_RGB:
                found["color"].append((i, vp))
    wanted: dict[str, tuple[int, int, int, str] | None] = {"depth": None, "color": None}
    if config is not None:
        wanted = {"depth": (*config.depth_mode, "z16"),
                  "color": (config.width, config.height, config.fps, "rgb8")}  # fmt: skip
    chosen = {kind: _choose(found[kind], wanted[kind], kind) for kind in found}
    groups: dict[int, list[Any]] = {}
    for i, vp in chosen.values():
        groups.setdefault(i, []).append(vp)
    depth_sensor = sensors[chosen["depth"][0]]
    depth, color = chosen["depth"][1], chosen["color"][1]
    try:
        e = depth.get_extrinsics_to(color)
    except RuntimeError as err:
        raise CameraError(f"the device has no depth->colour extrinsics ({err})") from err
    return Streams(
        device=device,
        sensors=[(sensors[i], profiles) for i, profiles in groups.items()],
        color_format=color.format().name,
        color_intrinsics=intrinsics_of(rs, color),
        depth_intrinsics=intrinsics_of(rs, depth),
        depth_to_color=Extrinsics.from_librealsense(e.rotation, e.translation),
        depth_scale_m=_depth_scale(rs, depth_sensor),
        info=_device_info(rs, device),
    )


def _choose(
    candidates: list[tuple[int, Any]], wanted: tuple[int, int, int, str] | None, kind: str
) -> tuple[int, Any]:
    for i, vp in candidates:
        if wanted is None or (vp.width(), vp.height(), vp.fps(), vp.format().name) == wanted:
            return i, vp
    offered = ", ".join(sorted({_mode(vp) for _, vp in candidates})) or "none"
    want = "any" if wanted is None else "{}x{}@{} {}".format(*wanted)
    raise CameraError(f"no {kind} stream {want}; the device offers: {offered}")


def _depth_scale(rs: Any, sensor: Any) -> float:
    if sensor.supports(rs.option.depth_units):
        return float(sensor.get_option(rs.option.depth_units))
    return 0.001


def _device_info(rs: Any, device: Any) -> dict[str, str]:
    info = {}
    for key, attr in _DEVICE_INFO.items():
        ci = getattr(rs.camera_info, attr)
        info[key] = str(device.get_info(ci)) if device.supports(ci) else ""
    return info


def configure(rs: Any, streams: Streams, config: RecordConfig) -> None:
    """Set the depth preset and emitter where asked, and global timestamps where possible."""
    for sensor, _ in streams.sensors:
        if sensor.supports(rs.option.global_time_enabled):
            sensor.set_option(rs.option.global_time_enabled, 1)
    depth_sensor = streams.sensors[0][0]
    for sensor, profiles in streams.sensors:
        if any(p.stream_type() == rs.stream.depth for p in profiles):
            depth_sensor = sensor
    if config.preset is not None:
        _set_preset(rs, depth_sensor, config.preset)
    if config.emitter is not None:
        if not depth_sensor.supports(rs.option.emitter_enabled):
            raise CameraError("this camera has no IR emitter to switch; leave --emitter out")
        depth_sensor.set_option(rs.option.emitter_enabled, 1 if config.emitter else 0)


def _set_preset(rs: Any, sensor: Any, name: str) -> None:
    option = rs.option.visual_preset
    if not sensor.supports(option):
        raise CameraError(f"this camera has no depth presets; leave --preset {name!r} out")
    r = sensor.get_option_range(option)
    names = {
        sensor.get_option_value_description(option, float(v)): float(v)
        for v in range(int(r.min), int(r.max) + 1)
    }
    key = {n.lower().replace("_", " "): v for n, v in names.items()}.get(
        name.lower().replace("_", " ")
    )
    if key is None:
        raise CameraError(f"unknown depth preset {name!r}; the camera has: {', '.join(names)}")
    sensor.set_option(option, key)
