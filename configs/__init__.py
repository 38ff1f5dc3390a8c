"""The built-in scenario and device files (``scenarios/*.toml``, ``devices/*.toml``), shipped as package data.

Found through :func:`importlib.resources.files` by :func:`gyroemu.dynamics.config.config_dir`.
"""
