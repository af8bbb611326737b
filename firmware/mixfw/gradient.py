# Gradients: a mix that changes with height or with the filament extruded, between
# virtual tools at two or more stops. Pure logic: imports on CPython too.
from mixfw.mixer import normalize

ALONG_Z = 0
ALONG_E = 1


class GradientError(ValueError):
    pass


class Gradient:
    def __init__(self, stops, along, alias, drives):
        """stops: [(position_mm, weights), ...] in increasing position; along: ALONG_Z or
        ALONG_E; alias: the tool that prints the gradient, or -1 for every tool."""
        if len(stops) < 2:
            raise GradientError("a gradient needs at least 2 stops")
        for (a, _), (b, _) in zip(stops, stops[1:]):
            if not b > a:
                raise GradientError("gradient stops must increase: %g then %g" % (a, b))
        self.stops = [(p, [w / sum(m) for w in m]) for p, m in stops]
        self.along = along
        self.alias = alias
        self.drives = drives

    def weights_at(self, pos_mm):
        """The normalised mix at a position: linear between stops, held beyond the ends.
        Integer weights sum to 10000, so steps are 0.01 %."""
        stops = self.stops
        if pos_mm <= stops[0][0]:
            shares = stops[0][1]
        elif pos_mm >= stops[-1][0]:
            shares = stops[-1][1]
        else:
            k = 0
            while stops[k + 1][0] < pos_mm:
                k += 1
            (a, ma), (b, mb) = stops[k], stops[k + 1]
            f = (pos_mm - a) / (b - a)
            shares = [(1 - f) * x + f * y for x, y in zip(ma, mb)]
        return normalize(shares, self.drives)
