# Freeze the firmware with the simulated board's settings. The simulated chip
# (simmachine.py, sim_main.py) is for the unix port and is not frozen.
module("board.py")
module("boot.py", base_path="../../firmware")
module("main.py", base_path="../../firmware")
package("mixfw", base_path="../../firmware")
