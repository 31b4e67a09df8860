"""The ``--clouds`` options shared by the commands that image or sample a sky (``skysim sky``,
``camera``, ``sample``): broken clouds (:class:`skysim.partly_cloudy.PartlyCloudySky`) in
front of the command's clear sky."""

from __future__ import annotations

from skysim.exceptions import InvalidParameterError

from .options import cloud_spec, float_in, wind_spec

__all__ = ["add_cloud_options", "with_clouds"]


def add_cloud_options(parser, *, wind: bool = False) -> None:
    """Add ``--clouds``, ``--cloud-scale``, ``--cloud-base`` (and ``--wind`` for commands
    whose samples span time)."""
    parser.add_argument(
        "--clouds", type=cloud_spec, default=None, metavar="COVER[,TAU[,SEED]]",
        help="a partly cloudy sky: cloud cover (fraction of the sky, 0-1), the clouds' "
             "optical thickness at 550 nm (0-100, default 10: stratocumulus) and the seed of "
             "the cloud field (default 0), e.g. 0.5,10,3 (default: clear)")
    parser.add_argument("--cloud-scale", type=float_in(0, 60, low_open=True, unit="deg"),
                        default=None, metavar="DEG",
                        help="with --clouds: size of the clouds seen overhead, the field's "
                             "correlation angle [deg] (default 10)")
    parser.add_argument("--cloud-base", type=float_in(50, 15000, unit="m"), default=None,
                        metavar="M", help="with --clouds: cloud base above the site [m] "
                                          "(default 1000)")
    if wind:
        parser.add_argument("--wind", type=wind_spec, default=None, metavar="SPEED,FROM",
                            help="with --clouds: wind at the cloud base, speed [m/s] and the "
                                 "azimuth it blows from [deg, clockwise from north], e.g. "
                                 "8,270: the clouds drift while the samples are taken "
                                 "(default: still)")


def with_clouds(sky, args, times=None):
    """``sky`` with the clouds of ``args`` in front of it (``sky`` itself without
    ``--clouds``); ``times``: the samples' times, one per sun position, for drifting clouds.

    Raises
    ------
    ValueError
        If a cloud option is given without ``--clouds``.
    """
    extra = [f for f, v in (("--cloud-scale", args.cloud_scale),
                            ("--cloud-base", args.cloud_base),
                            ("--wind", getattr(args, "wind", None))) if v is not None]
    if args.clouds is None:
        if extra:
            raise InvalidParameterError(f"{extra[0]} describes the clouds of --clouds; give --clouds "
                             "COVER[,TAU[,SEED]] too")
        return sky
    from skysim.cloud_field import CloudField
    from skysim.partly_cloudy import PartlyCloudySky
    cover, tau, seed = args.clouds
    speed, from_deg = getattr(args, "wind", None) or (0.0, 270.0)
    field = CloudField(cover, tau, seed,
                       correlation_deg=10.0 if args.cloud_scale is None else args.cloud_scale,
                       base_m=1000.0 if args.cloud_base is None else args.cloud_base,
                       wind_speed_m_s=speed, wind_from_deg=from_deg)
    out = PartlyCloudySky(sky, field)
    return out if times is None else out.at_times(times)
