# mixstep firmware: one module per concern; main.py assembles them from the board's settings.
