"""What goes in and out of files: run recordings (:mod:`.recording`), the
problem export and VTU files (:mod:`.export`), the fabrication drawing (SVG,
:mod:`.drawing`), pictures (:mod:`.plots`)
and progress on stderr (:mod:`.progress`)."""

from .._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    ".recording": ("Recorder", "RecordedRun", "RecordedStage", "HeldRun", "RecordingError", "read_recording"),
    ".export": ("write_export", "write_vtu", "EXPORT_KEYS"),
    ".drawing": ("write_svg",),
})
