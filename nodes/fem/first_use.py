"""The FEM node's first-use path table (:class:`FirstUseTable`, a part of :class:`nodes.fem.node.FemNode`):
a scene with no stored table has it built by :class:`flexsheet.fem.first_use_build.FirstUseBuild` (a worker
process at idle priority) while the linear model serves; progress goes to the log and the diagnostics
message; the table is attached when done, the force-depth republished from it, and that is said once. A
failed build is logged as an error and the linear model keeps serving."""

from __future__ import annotations

from flexsheet.fem.first_use import first_use_settings
from flexsheet.fem.first_use_build import FirstUseBuild
from flexsheet.fem.served import path_table_message

__all__ = ["FirstUseTable"]


class FirstUseTable:
    """The first-use half of the FEM node; it uses the node's ``scene``, ``model``, ``params``, ``log``,
    ``state_message`` and ``_publish_force_depth``."""

    def _start_first_use(self, cache_dir: str) -> None:
        """Start building the scene's path table on first use (module doc); the linear model serves meanwhile.
        """
        name = f"fem: scene {self.scene.name!r}"
        if not cache_dir:
            self.state_message = (f"{name}: no nonlinear path table stored and no disk cache to build one in "
                                  "(cache_dir \"\") - serving the LINEAR model")
            self.log.warning(self.state_message)
            return
        d = first_use_settings(self.scene)["depths"][-1]
        self._first_use = FirstUseBuild(self.model, str(self.scene.source or self.params.scene), cache_dir,
                                        self._first_use_progress, self._first_use_done,
                                        self._first_use_failed)
        k = self._first_use.spec.stations
        self.state_message = (f"{name}: no nonlinear path table stored - serving the LINEAR model while it "
                              f"is built on first use in the background ({k} stations to {d * 1e3:g} mm)")
        self.log.warning(self.state_message)
        self._first_use.start()

    def _first_use_progress(self, line: str) -> None:
        self.state_message = (f"fem: scene {self.scene.name!r}: serving the LINEAR model; first-use table: "
                              f"{line}")
        self.log.info(self.state_message)

    def _first_use_done(self, table: dict, line: str) -> None:
        """(The build's watcher thread.) Attach the table (about 1 s, beside the fingertips: one assignment
        when done), republish the force-depth from it, say so once."""
        self.model.attach_path_table(table)
        self._publish_force_depth()
        self.state_message = path_table_message(self.scene, self.model, f"built on first use, now served "
                                                f"({line})")
        self.log.info(self.state_message)

    def _first_use_failed(self, line: str) -> None:
        self.state_message = f"fem: scene {self.scene.name!r}: {line} - serving the LINEAR model"
        self.log.error(self.state_message)
