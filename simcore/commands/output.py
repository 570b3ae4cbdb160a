"""What the commands share: the output folder a user names, made before any work."""
import os


def output_folder(folder, option):
    """Create ``folder`` (an output folder the user named with ``option``) or raise a one-line OutputError."""
    from simcore.errors import OutputError
    from simcore.pipeline.store import check_writable
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the folder {folder} ({exc.strerror or exc}); choose another {option}") from None
    check_writable(os.path.join(folder, "probe"))
    return folder
