# Freeze the firmware with this board's pin map and settings. The port's own manifest
# comes first: it holds _boot.py, which mounts the flash filesystem the configuration
# (M500) and G-code files live on. The step path's modules (mixfw/inram.py) are
# frozen too, but the firmware runs them from copies in RAM, never from the flash
# cache: after flashing the image, `mixstep deploy --frozen` puts those copies on.
include("$(PORT_DIR)/boards/manifest.py")
module("board.py")
module("boot.py", base_path="../../firmware")
module("main.py", base_path="../../firmware")
package("mixfw", base_path="../../firmware")
