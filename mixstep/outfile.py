"""The files the host tools write: never over their input, and whole or not at all.

`replacing(path)` opens a temporary file beside path and renames it to path only when
the block ends without an error; on any error, Ctrl-C or SIGTERM included, the
temporary file goes and path keeps what it held. `refuse_input(out, *inputs)` stops a
command whose output names one of its inputs, before anything is opened."""
import os
import tempfile
from contextlib import contextmanager


class UsageError(Exception):
    """A mistake of the user's: the command says it in one line and exits with 2."""


def _same(a, b):
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them doesn't exist yet
        return os.path.realpath(a) == os.path.realpath(b)


def refuse_input(out_path, *in_paths, what="output"):
    """UsageError if out_path is one of in_paths (also through a link or another
    spelling of the path)."""
    if out_path in (None, "-"):
        return
    for p in in_paths:
        if p not in (None, "-") and _same(out_path, p):
            raise UsageError("the %s %s is the input file: write it to another file"
                             % (what, out_path))


@contextmanager
def replacing(path, mode="w", **open_args):
    """A file object for path's new content, written to a temporary file in path's
    folder (so the rename is atomic) and renamed over path at the end."""
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".part",
                               dir=folder)
    try:
        with os.fdopen(fd, mode, **open_args) as f:
            yield f
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


@contextmanager
def temporary_path(path):
    """A path beside `path` to write to (for writers that take a file name, such as
    matplotlib's savefig), renamed to path at the end, removed on any error."""
    folder = os.path.dirname(os.path.abspath(path))
    base, ext = os.path.splitext(os.path.basename(path))
    fd, tmp = tempfile.mkstemp(prefix="." + base + ".", suffix=".part" + ext, dir=folder)
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
