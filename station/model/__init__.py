"""The measurement model's optional physical effects, one module each.

The base model (scale factors, misalignments and biases of both triads, the inter-triad
rotation, and the nuisances of the bench) lives in ``station.estimate.lsq``; every effect here
adds parameters and a term to the predicted raw outputs.  ``LIBRARY`` (also ``EFFECTS``) maps
the library's ids to classes; station.model.registry adds the user's own (plugins).
"""
from station.model.accel_cross_axis import AccelCrossAxis
from station.model.accel_cubic import AccelCubic
from station.model.axis_offsets import RotationAxisOffsets
from station.model.bias_drift import BiasDrift
from station.model.bias_step import BiasStep
from station.model.effect import Effect, Param, SampleContext
from station.model.g_sensitivity import GyroGSensitivity
from station.model.gyro_anisoelastic import GyroAnisoelastic
from station.model.gyro_rate_nonlinearity import GyroRateNonlinearity
from station.model.lever_arm import AccelLeverArm
from station.model.nonlinearity import AccelNonlinearity
from station.model.remount import RemountPerSegment
from station.model.scale_asymmetry import GyroScaleAsymmetry
from station.model.scale_temperature import ScaleTemperature
from station.model.table_encoder_scale import TableEncoderScale
from station.model.table_vibration import TableVibration
from station.model.table_wobble import TableWobble
from station.model.temperature import TemperatureBias
from station.model.temperature_quadratic import TemperatureBiasQuadratic
from station.model.time_offset import TimeOffset

LIBRARY = {cls.id: cls for cls in (AccelLeverArm, AccelNonlinearity, GyroGSensitivity,
                                   GyroScaleAsymmetry, TemperatureBias, TimeOffset,
                                   AccelCubic, ScaleTemperature, TemperatureBiasQuadratic,
                                   GyroAnisoelastic, AccelCrossAxis, GyroRateNonlinearity,
                                   BiasDrift, BiasStep, TableEncoderScale,
                                   RotationAxisOffsets, TableWobble, TableVibration, RemountPerSegment)}
EFFECTS = LIBRARY

__all__ = ["EFFECTS", "LIBRARY", "Effect", "Param", "SampleContext"]
