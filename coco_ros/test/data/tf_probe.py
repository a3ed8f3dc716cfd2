"""``GraphProbe``: a test component that writes, every update, what the transformation graph holds
for a few frames (one JSON line: the edges between them with kind, stamp and value, and lookups),
so that a test can check from outside what a TFBridge ingested."""

from __future__ import annotations

import json

from coco_core import Attribute, Component


class GraphProbe(Component):
    path = Attribute(str, "graph.jsonl", "JSON-lines output")
    frames = Attribute(list[str], [], "frames whose edges are written")
    lookups = Attribute(list[str], [], "'target:source' lookups written")

    def on_config(self) -> None:
        self._file = open(self.path, "w")

    def on_update(self) -> None:
        graph = self.transform_graph
        wanted = set(self.frames)
        edges, values = {}, {}
        with graph.reading():  # one consistent state: the bridge writes the graph meanwhile
            for edge in graph.to_dict()["edges"]:
                if edge["parent"] in wanted and edge["child"] in wanted:
                    edges[f"{edge['parent']}->{edge['child']}"] = {
                        "kind": edge["kind"], "stamp": edge.get("stamp"), "transform": edge["transform"]}
            for text in self.lookups:
                target, source = text.split(":")
                try:
                    values[text] = graph.lookup(target, source).tolist()
                except LookupError:
                    pass
            frames = sorted(graph.frames)
        self._file.write(json.dumps({"frames": frames, "edges": edges, "lookups": values}) + "\n")
        self._file.flush()

    def on_stop(self) -> None:
        self._file.close()
