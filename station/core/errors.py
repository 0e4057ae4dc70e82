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


def cannot_write(path, error: OSError, what: str = "") -> UserError:
    """The one-line error for an output that could not be written.  Outputs given as a symbolic
    link are written through it, as the shell's ``>`` does (a link the user made on purpose
    keeps working); when that fails, the message names the link and where it points, so that
    "No such file or directory" about a path that is there in ``ls`` makes sense: a link whose
    target's folder does not exist, a link to a folder, a loop of links."""
    import errno
    import os

    where = f"{path}: cannot write{' ' + what if what else ''}"
    reason = error.strerror or str(error)
    try:
        is_link = os.path.islink(path)
    except (OSError, ValueError):
        is_link = False
    if is_link:
        try:
            target = os.readlink(path)
        except OSError:
            target = "?"
        resolved = os.path.join(os.path.dirname(os.fspath(path)), target)
        folder = os.path.dirname(resolved) or "."
        if error.errno == errno.ELOOP:
            why = "in a loop of symbolic links"
        elif not os.path.exists(resolved) and not os.path.isdir(folder):
            why = f"whose folder {folder} does not exist (a dangling link)"
        elif os.path.isdir(resolved):
            why = "which is a folder"
        else:
            why = f"({reason})"
        return UserError(f"{where}: a symbolic link to {target}, {why}; give another path or remove the link")
    return UserError(f"{where}: {reason}")
