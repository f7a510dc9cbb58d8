"""Tools around the twin judge (workflow/rules/judge.smk: candidate twins scored on the real slides, then the
Sim sets they make scored downstream) that run outside the results DAG.

    budget    where a profile's judge spends its device time, priced from the committed benchmarks
    reuse     an earlier judge run's candidates copied, so that a later run reruns only what changed

The judge's candidate twins and replays are the slide loop's (palpation.slides.twins); the choice among them is
report.twin_selection; its entry point is apps.twin_judge.
"""
