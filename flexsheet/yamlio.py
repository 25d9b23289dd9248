"""YAML the project reads from people (launch files, scene files): ``yaml.SafeLoader`` that refuses a key
given twice in one mapping. PyYAML keeps the last one silently, so a second ``nodes:`` or a repeated node name
would drop nodes without a word. Pure (PyYAML only)."""

from __future__ import annotations

import yaml

__all__ = ["UniqueKeyLoader"]


class UniqueKeyLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that raises ``yaml.constructor.ConstructorError`` ("found duplicate key 'x'", with
    the line and column) when a mapping repeats a key. Use as ``yaml.load(text, Loader=UniqueKeyLoader)``."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                dup = key in seen
            except TypeError:  # unhashable key: construct_mapping below reports it
                continue
            if dup:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping", node.start_mark, f"found duplicate key {key!r:.80}",
                    key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)
