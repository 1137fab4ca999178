"""Contracts shared by Python and C++: classes, split codes and the parity tolerances.

Each is written here once. The C++ side gets them from the generated header
``firmware_ref/include/fwref/contracts_gen.hpp`` (``python -m core.contracts --header``), and a test
checks that the committed header equals what this module generates.
"""

from __future__ import annotations

# Paper classes, in label order (label i = CLASS_NAMES[i]).
CLASS_NAMES: tuple[str, ...] = ("Healthy", "BatteryFault", "MotorFault", "OverheatFault")
N_CLASSES = len(CLASS_NAMES)
CLASS_LABELS: tuple[int, ...] = tuple(range(N_CLASSES))
HEALTHY = 0

# Split codes stored in dataset.npz's ``split`` array.
SPLITS: dict[str, int] = {"train": 0, "validation": 1, "test": 2}
SPLIT_TRAIN, SPLIT_VALIDATION, SPLIT_TEST = SPLITS["train"], SPLITS["validation"], SPLITS["test"]
