"""Validation campaigns: many varied runs of a scenario, their table and their success rates.

``grasp-campaign FILE --out DIR`` (:mod:`.command`): the file (:mod:`.spec`) expands into
runs; each runs on a Dask worker (:mod:`.engine`, :mod:`.run`) and its row is kept as it
finishes (:mod:`.store`); the report (:mod:`.report`) gives success rates with intervals.
"""
