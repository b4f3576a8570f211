"""A tiny third-party extractor package: it knows tendon_taichi only through the
public extraction protocol."""

from dataclasses import dataclass

from tendon_taichi.extraction import EXTRACTOR_API, Extractor, FiberView


class StrongestFiber(Extractor):
    """One tendon along the most tensioned fiber (the simplest possible plugin)."""

    name = "strongest"
    description = "one tendon along the most tensioned fiber (test plugin)"
    api = EXTRACTOR_API

    @dataclass
    class Options:
        pass

    def extract(self, problem, state, options):
        view = FiberView(problem)
        f = int(state.tau.argmax())
        return [view.tendon(int(view.edges[f][0]), [f], state)]


class Raises(Extractor):
    name = "raises"
    description = "always fails (test plugin)"
    api = EXTRACTOR_API

    def extract(self, problem, state, options):
        raise RuntimeError("this plugin always fails")


class Mutates(Extractor):
    """Breaks the rules: zeroes the tensions it was given, in place."""

    name = "mutates"
    description = "edits state.tau in place (test plugin)"
    api = EXTRACTOR_API

    def extract(self, problem, state, options):
        state.tau[:] = 0.0
        return []


class DamagedWaypoints(StrongestFiber):
    """Breaks the rules: the strongest fiber's tendon with its waypoints changed
    by :meth:`damage` (not registered itself; its subclasses are)."""

    def damage(self, waypoints):
        raise NotImplementedError

    def extract(self, problem, state, options):
        t = super().extract(problem, state, options)[0]
        t.waypoints = self.damage(t.waypoints)
        return [t]


class Outside(DamagedWaypoints):
    """A tendon whose waypoints lie 1 m beside its nodes."""

    name = "outside"
    description = "returns waypoints far outside the body (test plugin)"

    def damage(self, waypoints):
        return waypoints + 1.0


class NanWaypoints(DamagedWaypoints):
    """A tendon with NaN waypoints."""

    name = "nan_waypoints"
    description = "returns NaN waypoints (test plugin)"

    def damage(self, waypoints):
        return waypoints * float("nan")


class Sleeps(Extractor):
    """Breaks the rules: takes ten minutes."""

    name = "sleeps"
    description = "sleeps for ten minutes (test plugin)"
    api = EXTRACTOR_API

    def extract(self, problem, state, options):
        import time

        time.sleep(600)
        return []
