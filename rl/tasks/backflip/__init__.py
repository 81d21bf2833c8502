"""The paper's backflip: the FSM task and its terms."""
