"""mixstep host tools: run the firmware in simulation, and work with its traces."""
