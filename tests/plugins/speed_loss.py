"""A law of the drive as a plugin (docs/extending.md, "A law of the sensor or
the drive"): a torque reading that grows with speed,
``tau_measured_j = (1 + c_j |qd_j|) tau_j``."""

import numpy as np

from bench.physics.sensor_laws import JointTorqueLaw, register


@register
class SpeedLoss(JointTorqueLaw):
    """tau_measured_j = (1 + c_j |qd_j|) tau_j"""

    name, kind, parameter, neutral, bounds = "speed_loss", "drive", "c", 0.0, (0.0, 0.5)

    @classmethod
    def law_text(cls, term, parameter):
        j = term.joint + 1
        return f"tau_measured_{j} = (1 + {parameter}*|qd_{j}|)*tau_{j}"

    def joint_factor(self, data):
        return 1 + self.value * np.abs(data.qd[:, self.joint])

    def joint_column(self, tau_hat, data):
        return tau_hat * np.abs(data.qd[:, self.joint]) / self.joint_factor(data)
