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
