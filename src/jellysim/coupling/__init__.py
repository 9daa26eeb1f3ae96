"""The coupling between bodies (DESIGN §1, paper §4.2.2-4.2.4): the soft bell stepped in its
water (:mod:`.bell_in_fluid`) and the margin recorded from it that drives the tentacle roots
(:mod:`.margin`). It imports the physics packages and nothing above them."""
