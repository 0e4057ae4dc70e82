"""Errors that the command line reports to the user as one line (exit status 2)."""


class UserError(Exception):
    """An error caused by the user's input: the CLI prints str(e) as ONE line on stderr and exits 2."""


class CaptureError(UserError):
    """A capture bundle that does not follow docs/capture.md (station-capture/1).

    str() names the file, then the segment, line and field when known:
    ``"cap/manifest.yaml: segments[2] (rot1p): field 'rate_dps': must be a finite number"``,
    ``"cap/rot1p.csv: segments[2] (rot1p): line 12: column 'gx': not a number: 'abc'"``.
    """

    def __init__(self, file, message, *, line=None, field=None, segment=None):
        self.file = str(file)
        self.message = message
        self.line = line
        self.field = field
        self.segment = segment
        super().__init__(str(self))

    def __reduce__(self):           # pickled whole (a forked reader sends it to its parent)
        return (_capture_error, (self.file, self.message, self.line, self.field, self.segment))

    def __str__(self):
        parts = [self.file]
        if self.segment is not None:
            parts.append(self.segment)
        if self.line is not None:
            parts.append(f"line {self.line}")
        if self.field is not None:
            parts.append(f"field '{self.field}'")
        parts.append(self.message)
        return ": ".join(parts).replace("\r", " ").replace("\n", " ")


def _capture_error(file, message, line, field, segment) -> CaptureError:
    return CaptureError(file, message, line=line, field=field, segment=segment)
