// A scene source with no header of its name: core_layering_catches_violations expects it named.
