"""The products form of the paper model (``RobotModel(form="products")``) on a one-joint robot
under the single-joint names (``ident.models.new_model``: a_m_J, b_m_J, ..., a_m, b_m, ...,
c_m, d_m, c_g, d_g, F_V, tau_off), through ``single_joint_map`` (J = ZZ3R, MX = -MY3, ...)."""

from __future__ import annotations

import numpy as np

from ident.robot.base import SingleJointMap
from ident.robot.estimate import RobotModel

TAIL = {"c_m": "c_m", "d_m": "d_m", "c_g": "c_g", "d_g": "d_g", "F_V": "FV", "tau_off": "OFF"}


def products_as_single(est: RobotModel, smap: SingleJointMap
                       ) -> tuple[dict[str, float], dict[str, float]]:
    """(values, standard deviations) of a fitted one-joint products model by the single-joint
    names: each product family's base-column vector mapped by ``smap.matrix`` (its
    covariance by the same linear map), the payload torque's products and the tail by name
    (the fixed ones -- no payload -- left out, as the single-joint model leaves them out)."""
    (n,) = est.numbers_
    cols = est.cols_[0]
    rows, names = [], []
    index = {name: i for i, name in enumerate(est.names_)}
    for pre in ("a_m", "b_m", "a_g", "b_g"):
        for r, single in zip(smap.matrix, smap.names, strict=False):
            if single not in ("J", "MX", "MY"):
                continue
            row = np.zeros(len(est.names_))
            for c in cols:
                row[index[f"{pre}_{est.theta_names_[c]}_{n}"]] = r[c]
            rows.append(row)
            names.append(f"{pre}_{single}")
        if f"{pre}{n}" not in est.fixed_:
            row = np.zeros(len(est.names_))
            row[index[f"{pre}{n}"]] = 1.0
            rows.append(row)
            names.append(pre)
    for single, robot in TAIL.items():
        row = np.zeros(len(est.names_))
        row[index[f"{robot}{n}"]] = 1.0
        rows.append(row)
        names.append(single)
    M = np.array(rows)
    val = M @ est.coef_
    std = np.sqrt(np.diag(M @ est.cov_ @ M.T))
    return (dict(zip(names, val.tolist(), strict=True)),
            dict(zip(names, std.tolist(), strict=True)))
