"""The loop's self-tests: measured-like sets made by the twin with a known truth, then the loop on each, as in real use.

    fixed               the fixed case list (loop.selftest.cases), and what every run shares: the injection, the
                        set made and saved, the loop on all sets in lockstep, the scored rows
    generative          every run draws its own truth (loop.generative settings): the measure of issue 40
    generative_report   the generative runs' summary, CSV and page

Their settings are part of the loop's config, below the state loop (loop.selftest_config, loop.generative_config),
as is the library of effects outside the candidate list that both inject (loop.unlisted).
"""
