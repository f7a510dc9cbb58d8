"""The slide loop: the residual loop on measured slides (sequence sets), in the twin of the real scene.

    replay        the scene, the pose schedule, markers per measured frame and the motion metrics
    selection     the trials and frames of a sequence set the loop works on
    folds         the two folds of trials (cross-fitting); fold_batches: both folds' twin calls as one batch
    loop          the rounds per fold: search each candidate effect, keep the best if the gate passes
    gate          the inner gate: an effect kept only if fits that left out a trial score it better
    twins         a fold's fitted twin as a twin option, and any twin replayed on the slides its fit never saw
    diagnosis     what the real slides' motion is made of, and what a held-out MAE can reach without a twin

The photo loop (palpation.loop) lies below: its residual modes (loop.residual) name a slide's residual too.
"""
