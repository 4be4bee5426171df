"""The built-in commands; importing this package registers them with :mod:`hbgear.cli`."""

import importlib

for _name in ("frc", "solve", "simulate", "stability_map", "validate"):
    try:
        importlib.import_module(f"{__name__}.{_name}")
    except ModuleNotFoundError as error:  # a command whose module is not shipped
        if error.name != f"{__name__}.{_name}":
            raise
