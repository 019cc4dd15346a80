"""The names of the log formats `data.format` may take: the built-in readers' and any that
gpquad.data.io.register_reader adds (the config checks read this, not the readers)."""

FORMATS: set[str] = {"generic", "px4-csv", "ulog", "betaflight", "table", "ardupilot"}
