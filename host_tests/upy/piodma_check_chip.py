# piodma.check_chip for a board's chip against what MicroPython says it runs on (its
# machine name and DMA's CHAIN_TO bit): "ok" or the refusal, for each case.
import json

from mixfw import piodma

res = []
for chip, cpu, lsb in (("rp2040", "Raspberry Pi Pico with RP2040", 11),
                       ("rp2350", "Raspberry Pi Pico2 with RP2350", 13),
                       ("rp2350", "Raspberry Pi Pico2 with RP2350-RISCV", 13),
                       ("rp2040", "Raspberry Pi Pico2 with RP2350", 13)):
    try:
        piodma.check_chip(chip, cpu, lsb)
        res.append("ok")
    except ValueError as e:
        res.append(str(e))
print(json.dumps(res))
