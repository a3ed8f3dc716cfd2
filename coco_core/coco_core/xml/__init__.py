"""Application files: XML in, :class:`~coco_core.model.AppSpec` out.

The dialect is the original CoCo launcher's, in both of its layouts, with its ``<pipeline>``,
``<farm>`` and ``$(eval)``, and a few extensions (args, substitutions, conditions, ``on_error``,
``event``, ``<transforms>``); ``docs/xml_format.md`` describes it and ``docs/coco.xsd`` is its
schema. Loading checks everything that can be checked without importing a component and reports
every problem with its file and line.
"""

from .loader import load_application, parse_application_string

__all__ = ["load_application", "parse_application_string"]
