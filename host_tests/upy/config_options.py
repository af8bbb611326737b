# The options of configurations from the board's settings: their names, those that
# need a restart, those without a bed, soft_limits' default, and the refusal of a
# board default out of range.
import json

import board
from config_unit import Flash, PATH
from mixfw.config import Config, ConfigError

c = Config(board.SETTINGS, PATH, Flash())
no_bed = {k: v for k, v in board.SETTINGS.items() if not k.startswith("bed_")}
d = Config(no_bed, PATH, Flash())
try:
    Config(dict(board.SETTINGS, drives=9), PATH, Flash())
    bad = None
except ConfigError as e:
    bad = str(e)
print(json.dumps({"names": [o.name for o in c.options],
                  "restart": [o.name for o in c.options if o.restart],
                  "no_bed": [o.name for o in d.options],
                  "soft_limits": c.settings["soft_limits"], "bad": bad}))
