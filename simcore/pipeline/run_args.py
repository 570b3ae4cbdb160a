"""The command-line options of ``sunsim run`` that choose its epochs and its recorded attitude
(:mod:`simcore.pipeline.schedule`). Kept apart from cli.py (no heavy imports: the parser is built at start-up)."""


def add_attitude_options(p):
    """Add --attitude, --attitude-frame, --attitude-direction and --times to the ``run`` parser ``p``."""
    p.add_argument("--attitude", metavar="FILE",
                   help="recorded attitude history (overrides the tumble): a CSV time_utc,qw,qx,qy,qz (absolute UTC; "
                        "'# frame:' and '# direction:' lines may declare its convention), a relative-time CSV "
                        "t_s,qw,qx,qy,qz (its first row is --start, which it then needs), an OPS-SAT GRAINS export "
                        "or 2021 log. Unless declared, the quaternion is scalar first, in GCRF, and rotates body "
                        "vectors into the frame (v_frame = R(q) v_body). Without --start/--duration an absolute "
                        "history is rendered at its own trusted sample times; gaps, jumps and frozen stretches are "
                        "left out, never interpolated (docs/attitude_history.md)")
    p.add_argument("--attitude-frame", choices=["GCRF", "EME2000", "TEME", "TOD"], default=None,
                   help="the inertial frame of the --attitude quaternions where the file does not declare it "
                        "(default GCRF)")
    p.add_argument("--attitude-direction", choices=["body_to_frame", "frame_to_body"], default=None,
                   help="body_to_frame: v_frame = R(q) v_body (default); frame_to_body: v_body = R(q) v_frame")
    p.add_argument("--times", metavar="FILE",
                   help="render at these epochs (one ISO-8601 UTC time per line, any spacing) instead of "
                        "--start/--duration/--step")
