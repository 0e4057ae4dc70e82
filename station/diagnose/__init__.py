"""Compare the model with the measurements (docs/diagnose.md)."""
from station.core.errors import UserError

# what a diagnosis needs once the capture is summarised, imported while a forked child reads the
# capture (station.estimate.summarise_while_importing): here, so that naming them imports nothing
DIAGNOSIS_MODULES = ("station.estimate.lsq", "station.diagnose.auto", "station.diagnose.core",
                     "station.diagnose.pipeline")


class RotationWithoutAngle(UserError):
    """A rotation segment without its encoder angle, not a hand turn: the least-squares model
    (the diagnosis) cannot use the capture."""


def segment_check(capture):
    """The check_segment of a diagnosis: refuses (RotationWithoutAngle) a rotation without its encoder angle that
    no hand made (the least-squares model cannot use it); raised at once when there is no static
    for a hand turn to lie between (a screwdriver's capture).  Static segments quantised coarser
    than their noise (a dead axis) are refused as estimate refuses them (UserError)."""
    message = (f"{capture.path}: diagnose fits the least-squares model, which needs the encoder "
               "angle (angle_deg) of every rotation segment that is not a hand turn between statics")
    if not capture.complete("static") and any(seg.angle_deg is None for seg in capture.complete("rotation")):
        raise RotationWithoutAngle(message)

    def check(seg) -> None:
        from station.estimate import check_static_resolution
        from station.estimate.hand_rotation import is_hand

        if seg.kind == "static":        # as estimate: a dead or coarsely quantised axis is refused
            check_static_resolution(capture, seg)
        if seg.kind == "rotation" and seg.angle_deg is None and not is_hand(seg):
            raise RotationWithoutAngle(message)
    return check
