# For each configuration on stdin (JSON: lists of [option, value text]): the M503 lines
# after setting it with M926, and those of a fresh configuration given those lines.
import json
import sys

import board
from config_unit import Commands, Flash, PATH
from mixfw.config import Config

# Streamed, one configuration at a time: the whole answer as one string would need a
# block of about a megabyte.
sys.stdout.write("[")
for k, pairs in enumerate(json.loads(sys.stdin.read())):
    a = Commands(Config(board.SETTINGS, PATH, Flash()))
    for name, text in pairs:
        a.send("M926 I%s V%s" % (name, text))
    a.send("M503")
    b = Commands(Config(board.SETTINGS, PATH, Flash()))
    for line in a.lines:
        b.send(line[len("echo:"):])
    b.send("M503")
    if k:
        sys.stdout.write(",")
    json.dump((a.lines, b.lines), sys.stdout)
print("]")
