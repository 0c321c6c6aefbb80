"""The foundation every layer stands on: tolerances (:mod:`.tolerances`), exact arithmetic (:mod:`.exact`), thread
counts (:mod:`.threads`), the registries that plugins extend (:mod:`.registry`), the checks of every argument
(:mod:`.validation`), progress lines (:mod:`.progress`), optional extras (:mod:`.extras`) and where the modules of
earlier releases live now (:mod:`.moved`). It imports nothing else of the package."""
