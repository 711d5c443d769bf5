# SPDX-License-Identifier: Apache-2.0
"""Python client of armfw's network API (docs/api.md, docs/python.md)."""
from .client import Arm, ArmError, ArmStopped, Stream, Subscription

__all__ = ["Arm", "ArmError", "ArmStopped", "Stream", "Subscription"]
