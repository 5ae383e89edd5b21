"""What the episodes and runs tell: clinical movement metrics (:mod:`.metrics`), evaluation
reports (:mod:`.evaluation`), traces on disk (:mod:`.traces`), the paper's figures
(:mod:`.figures`, :mod:`.learning_curves`, :mod:`.plotting`) and videos (:mod:`.video`).

matplotlib and imageio are imported only when a figure or a video is made.
"""
