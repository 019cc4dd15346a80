"""User-facing errors: one line naming the file, the field and the fix."""


class GpquadError(Exception):
    """An error caused by the user's input (data or config), printed as one line by the CLI."""

    def __init__(self, message: str, *, source: str | None = None, field: str | None = None):
        self.source = source
        self.field = field
        where = ", ".join(p for p in (source and f"{source}", field and f"field '{field}'") if p)
        super().__init__(f"{where}: {message}" if where else message)
