"""What goes in and out of files: run recordings (:mod:`.recording`), the
problem export, VTU and SVG files (:mod:`.export`), pictures (:mod:`.plots`)
and progress on stderr (:mod:`.progress`)."""

from .._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    ".recording": ("Recorder", "RecordedRun", "RecordedStage", "RecordingError", "read_recording"),
    ".export": ("write_export", "write_vtu", "write_svg", "EXPORT_KEYS"),
})
