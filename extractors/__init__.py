"""The built-in tendon extractors, registered as plugins exactly as a third-party
package would be (entry points in the group ``tendon_taichi.extractors``).

They import only the public protocol, :mod:`tendon_taichi.extraction`.

* ``strands`` - greedy strand tracing (straightest, similar-tension continuation).
* ``network_discovery`` - a re-creation of the two-stage baseline of Bern et al. 2017.
* ``path_cover`` - a global path cover by per-node maximum-weight matching.
"""
