# A Wi-Fi chip's `network` module for the test of webserver.board_listeners: the
# station interface is connected while CONNECTED[0] is true. A folder of its own, put
# on sys.path by that test only: any other firmware run must find no network.
STA_IF = 0
CONNECTED = [False]


class WLAN:
    def __init__(self, interface):
        self.interface = interface

    def isconnected(self):
        return CONNECTED[0]
