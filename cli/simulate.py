"""``hybridneus simulate``: render a mesh and simulate a colour event camera (EventNeRF layout)."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Annotated

import typer


class Spiral(str, Enum):
    seiffert = "seiffert"
    even = "even"
    circle = "circle"


class NoisePreset(str, Enum):
    none = "none"
    real = "real"
    davis346 = "davis346"


def simulate(
    source: Annotated[str, typer.Argument(
        help="Mesh file (OBJ with MTL/textures, PLY, OFF, GLB) or a built-in scene: "
             "builtin:device, builtin:thin, or generated:KIND:SEED (KIND: box, slab, cage, "
             "bowl, blob, rods).", show_default=False)],
    out: Annotated[Path, typer.Argument(help="Output dataset folder (replaced atomically).",
                                        show_default=False)],
    views: Annotated[int, typer.Option(help="Training views along the spiral.")] = 999,
    revolutions: Annotated[float, typer.Option(help="Turns of the training spiral.")] = 8.0,
    spiral: Annotated[Spiral, typer.Option(
        help="seiffert: constant speed (the paper's; most views near the equator); "
             "even: constant elevation change per turn; circle: constant --elevation "
             "(a turntable; --revolutions 1 wraps around).")] = Spiral.seiffert,
    elevation: Annotated[float, typer.Option(
        help="Elevation in degrees of --spiral circle.")] = 30.0,
    width: Annotated[int, typer.Option(help="Image width in pixels.")] = 346,
    height: Annotated[int, typer.Option(help="Image height in pixels.")] = 260,
    fov: Annotated[float, typer.Option(help="Vertical field of view in degrees.")] = 55.0,
    object_radius: Annotated[float, typer.Option(
        help="Bounding-sphere radius of the normalised object (cameras at 1/1.1).")] = 0.4,
    supersample: Annotated[int, typer.Option(
        help="Rays per pixel along each axis (anti-aliasing).")] = 2,
    threshold: Annotated[float | None, typer.Option(
        help="Contrast threshold C (log units). [default: 0.2; with --noise davis346 the "
             "DAVIS346's]", show_default=False)] = None,
    eps: Annotated[float, typer.Option(help="eps in log(I^2.2 + eps).")] = 1e-3,
    sensor: Annotated[str, typer.Option(
        help="The sensor's colour filter: a Bayer layout (RGGB, BGGR, GRBG, GBRG) or mono "
             "(every pixel sees the mean of the three channels).")] = "RGGB",
    k1: Annotated[float, typer.Option(help="Radial distortion k1 (writes 5x4 intrinsics).")] = 0.0,
    k2: Annotated[float, typer.Option(help="Radial distortion k2.")] = 0.0,
    noise: Annotated[NoisePreset, typer.Option(
        help="none; real: threshold mismatch 0.03, background activity, hot pixels and a "
             "polarity offset of -0.4; davis346: a DAVIS346 at indoor light (its ON/OFF "
             "thresholds, mismatch, 0.1 Hz background activity, hot pixels at 100 Hz, 0.5 ms "
             "refractory period, 0.1 ms timestamp jitter; docs/simulate.md), views "
             "--view-seconds apart. Each is overridable below.")] = NoisePreset.none,
    view_seconds: Annotated[float, typer.Option(
        help="Seconds between views, for --noise davis346's rates.")] = 0.03,
    jitter: Annotated[float | None, typer.Option(
        help="Timestamp jitter (standard deviation) in frame units.")] = None,
    threshold_sigma: Annotated[float | None, typer.Option(
        help="Per-pixel threshold standard deviation.")] = None,
    background_rate: Annotated[float | None, typer.Option(
        help="Background-activity events per pixel per frame interval.")] = None,
    hot_pixels: Annotated[float | None, typer.Option(
        help="Fraction of hot pixels.")] = None,
    hot_pixel_rate: Annotated[float | None, typer.Option(
        help="Events per hot pixel per frame interval.")] = None,
    refractory: Annotated[float | None, typer.Option(
        help="Refractory period in frame units.")] = None,
    polarity_offset: Annotated[float | None, typer.Option(
        help="Polarity imbalance o: C_pos = C(1+o), C_neg = C(1-o); written to the preset.")]
        = None,
    seed: Annotated[int, typer.Option(help="Seed of the noise generators.")] = 0,
    pose_noise: Annotated[float, typer.Option(
        help="Realistic capture: RMS error (degrees) of each written training pose's "
             "rotation; the true poses go to train/pose_true/.")] = 0.0,
    pose_noise_translation: Annotated[float, typer.Option(
        help="RMS error of each written camera centre, as a share of its distance from the "
             "object (0.01: 1%).")] = 0.0,
    clock_offset: Annotated[float, typer.Option(
        help="Written pose k is the true pose at k + this (views): a clock offset.")] = 0.0,
    pose_drift_views: Annotated[float, typer.Option(
        help="Pose errors drawn every this many views and interpolated between (a drift); "
             "0: each view's drawn on its own.")] = 0.0,
    light: Annotated[str | None, typer.Option(
        help="World direction towards the light, X,Y,Z (+y is up). [default: 0.4,1,0.6]",
        show_default=False)] = None,
    headlight: Annotated[bool, typer.Option(
        "--headlight", help="Light from the camera instead of --light (shading that moves "
                            "with the view).")] = False,
    ambient: Annotated[float, typer.Option(
        help="Ambient term of the Lambertian shading (1 with --diffuse 0: unlit albedo).")]
        = 0.35,
    diffuse: Annotated[float, typer.Option(help="Diffuse (n . l) term.")] = 0.65,
    background: Annotated[str | None, typer.Option(
        help="Background sRGB in [0, 1]: one grey value or R,G,B; written to the preset. "
             "[default: 159/255 grey]", show_default=False)] = None,
    val_views: Annotated[int, typer.Option(
        help="Views of the validation split (a circle at 30 deg elevation); 0 skips it.")] = 100,
    test_views: Annotated[int, typer.Option(
        help="Views of the test split (an even spiral, 60 to 5 deg); 0 skips it.")] = 200,
    threads: Annotated[int, typer.Option(help="Ray-casting threads (0 = all cores).")] = 0,
    rgb: Annotated[bool, typer.Option(help="Write rgb/r_*.png frames.")] = True,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
) -> None:
    """Render SOURCE along a camera spiral and simulate a colour (RGGB) or mono event camera.

    Writes OUT in the EventNeRF layout: train, validation and test splits.

    Each split holds intrinsics/, pose/, rgb/ and events/events.npz; OUT also gets gt_mesh.ply.

    OUT/scene.json records everything, with a "preset" (threshold, eps, crop) for the reader.

    Example: hybridneus simulate builtin:device data/sim/device --views 300
    """
    from dataclasses import replace

    from hybridneus.errors import ConfigError
    from hybridneus.simulate import (
        DAVIS346_THRESHOLD,
        REALISTIC_NOISE,
        CaptureErrors,
        EventModel,
        NoiseConfig,
        Shading,
        SimulationConfig,
        davis346_noise,
        simulate_dataset,
    )

    if not view_seconds > 0:
        raise ConfigError(f"--view-seconds: must be > 0, got {view_seconds}")
    base_noise = {NoisePreset.real: REALISTIC_NOISE,
                  NoisePreset.davis346: davis346_noise(view_seconds)}.get(noise, NoiseConfig())
    offset = {NoisePreset.real: -0.4, NoisePreset.davis346: DAVIS346_THRESHOLD[1]}.get(noise,
                                                                                        0.0)
    if threshold is None:
        threshold = DAVIS346_THRESHOLD[0] if noise is NoisePreset.davis346 else 0.2
    if polarity_offset is not None:
        offset = polarity_offset
    changes = {k: v for k, v in {
        "threshold_sigma": threshold_sigma, "background_rate": background_rate,
        "hot_pixel_fraction": hot_pixels, "hot_pixel_rate": hot_pixel_rate,
        "refractory": refractory, "jitter": jitter}.items() if v is not None}
    for key, value in changes.items():
        if value < 0:
            raise ConfigError(f"--{key.replace('_', '-')}: must be >= 0, got {value}")
    looks: dict = {"ambient": ambient, "diffuse": diffuse, "headlight": headlight}
    if light is not None:
        looks["light_dir"] = _floats("--light", light, (3,))
    if background is not None:
        bg = _floats("--background", background, (1, 3))
        looks["background"] = bg * 3 if len(bg) == 1 else bg
    try:
        shading = Shading(**looks)
        config = SimulationConfig(
            n_views=views, revolutions=revolutions, spiral=spiral.value,
            elevation_deg=elevation, width=width,
            height=height, fov_y_deg=fov, object_radius=object_radius, distortion=(k1, k2),
            supersample=supersample,
            events=EventModel(threshold=threshold, eps=eps, polarity_offset=offset,
                              mosaic=sensor),
            noise=replace(base_noise, **changes), shading=shading, seed=seed, val_views=val_views,
            test_views=test_views, n_threads=threads, write_rgb=rgb,
            capture=CaptureErrors(pose_noise, pose_noise_translation, clock_offset, seed,
                                  smooth_views=pose_drift_views))
    except ValueError as exc:
        raise ConfigError(f"simulate: {exc}") from None
    info = simulate_dataset(source, out, config, progress=not quiet)
    for name, split in info["splits"].items():
        typer.echo(f"{name}: {split['n_views']} views, {split['n_events']:,} events "
                   f"({split['trajectory']})")
    typer.echo(f"wrote {out} in {info['seconds']:.1f} s")


def _floats(option: str, text: str, counts: tuple[int, ...]) -> tuple[float, ...]:
    """Parse a comma-separated list of numbers with one of the allowed lengths."""
    from hybridneus.errors import ConfigError

    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) not in counts:
        want = " or ".join(str(c) for c in counts)
        raise ConfigError(f"{option}: expected {want} comma-separated numbers, got {text!r}")
    return values
