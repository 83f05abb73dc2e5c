"""The error every layer raises for bad input (config fields, schedules, study storages)."""


class ConfigError(ValueError):
    """A configuration value is out of range; the message is one line for the user."""
