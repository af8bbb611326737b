# A corrupt file beside the complete .tmp of an interrupted save: the boot's settings,
# its warnings and the files it leaves.
import json

import board
from config_unit import Flash, PATH
from mixfw.config import Config

new = Config(board.SETTINGS, PATH, Flash())
new.update((("steps_per_mm_x", 90.0), ("drives", 2)))
flash = Flash({PATH: b"garbage\n", PATH + ".tmp": new.text()})
warnings = []
c = Config(board.SETTINGS, PATH, flash, warnings.append)
c.boot()
print(json.dumps({"same": c.settings == new.settings, "warnings": warnings,
                  "files": sorted(flash.files), "moved": flash.files[PATH] == new.text()}))
