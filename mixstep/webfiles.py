"""The web page's files as the firmware serves them: each of firmware/web/ gzipped
(`<name>.gz`), the way they go on a board's flash (`mixstep deploy`) and into the
simulated printer's (`mixstep serve --http`)."""
import gzip
from pathlib import Path

from mixstep import paths

SOURCE = paths.ROOT / "firmware" / "web"


def build(dest):
    """Write SOURCE's files gzipped into dest; returns {name.gz: bytes}. The same
    bytes every time (no time stamp), so a deploy sends only what changed."""
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    sizes = {}
    for src in sorted(SOURCE.iterdir()):
        if src.is_file():
            data = gzip.compress(src.read_bytes(), compresslevel=9, mtime=0)
            (dest / (src.name + ".gz")).write_bytes(data)
            sizes[src.name + ".gz"] = len(data)
    return sizes
