# mixstep firmware: one module per concern; assemble.py assembles them from the board's settings.
