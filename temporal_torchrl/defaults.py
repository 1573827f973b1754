"""The defaults the library, the recipes' config schemas and the presets share, each written once.

The reward (:class:`~temporal_torchrl.rewards.TemporalReward`, the reward functions), its
finetuning (the losses in :mod:`temporal_torchrl.objectives`, the trainer, the replay's
finetuning sampler), the k-step history and relay exploration default to these values, and so do
the recipe's config schemas (:mod:`temporal_torchrl.configs`), which read them from here: a piece
composed from the API with its defaults is the one ``recipes/sac_temporal.py`` trains with its
own, the thesis's best, FuRL with D3 at rho 1, lambda 4 (section 5.3.3, Table 5.12). The thesis's
other configurations are the recipe's presets (``recipes/preset/``).

The env's and the scripted experts' settings (camera, episode length, goal setting) and the
offline reward-quality benchmark's dataset are here too: the library's signatures, the recipes'
schemas and :class:`~temporal_torchrl.reward_quality.DatasetSpec` read them, so a quantity has
one value whichever door it comes in by.

The module imports nothing, so the config schemas stay free of torch.
"""

#: The positional reward r_P (thesis 3.1.3, FuRL).
POSITIONAL_REWARD = "furl"
#: The directional reward r_D (thesis 4.3.2, D3: position and direction).
DIRECTIONAL_REWARD = "d3"
#: The baseline text b: the generic b_g, not the task's tailored b_t (thesis 4.2.2); the best
#: reward's (Table 5.12).
BASELINE = "generic"
#: rho, the weight of the VLM reward in r_t = r^task_t + rho (r_P + lambda r_D) (thesis 4.1).
RHO = 1.0
#: lambda, the weight of the directional reward relative to the positional one (thesis 4.1).
LAMBDA = 4.0
#: k, the history offset of s_{t-k} in the direction s_t - s_{t-k} (thesis 4.3).
K = 5
#: alpha, the goal-baseline regularisation strength of P3, P4 and D5 (thesis 3.1.2, eq. 4.5).
ALPHA = 0.4
#: The goal-baseline projection forms: onto the direction g - b from the origin (the thesis's
#: release) or onto the line through b and g (VLM-RMs); see
#: :mod:`~temporal_torchrl.rewards.positional`.
PROJECTIONS = ("origin", "line")
#: The goal-baseline projection (``"origin"``, the thesis's release).
PROJECTION = "origin"
#: The window length K, the embeddings s_{t-K+1} .. s_t a window reward (d_sequence) reads
#: (beyond the thesis, section 6.3 proposal); the registry option ``window``
#: (``reward.options.window``), ``window_length`` in Python.
WINDOW_LENGTH = 8
#: beta and c of the certainty estimate (beyond the thesis, section 6.4 proposal): the kernel
#: bandwidth in units of the references' median distances, and the pseudo-count of "unsure".
#: Calibrated on the reward-quality benchmark's six tasks with the shipped encoder
#: (docs/results/beyond_thesis/certainty_calibration.md): beta = 0.2 lets the position kernel
#: alone decide, a random direction at an expert's position gets a target of +0.08; beta = 0.1,
#: the widest of the grid that keeps it at 0.00, is the default.
CERTAINTY_BANDWIDTH = 0.1
CERTAINTY_PRIOR = 1.0
#: delta, the margin of FuRL's ranking loss l_delta (thesis 3.1.3).
DELTA = 0.1
#: How much closer to the goal image s_g a negative must be to be preferred in the finetuning
#: stage-1 ranking loss (the thesis's release).
L2_MARGIN = 0.2
#: The directional loss's contrasted terms at the variant's own position (the thesis text, 4.3.3);
#: False: the release's plain position for D4 and D5.
SAME_POSITION = True
#: States of each kind per finetuning batch (the thesis release).
HEADS_BATCH_SIZE = 256
#: The heads' Adam learning rate (the thesis release, LukasWill/directional_vlm_rl).
HEADS_LEARNING_RATE = 1e-4
#: The finetuning stages (thesis 3.1.3): 1 from failed episodes only, 2 with successful ones
#: (not the protocol stages of section 5.1, ``protocol=stage1|stage2``).
STAGES = (1, 2)
#: The finetuning samples its positive and negative states from the most recent this many of
#: each kind (FuRL's FIFO of 20,000; the thesis release).
LABEL_WINDOW = 20_000
#: The lag of the positional loss's pos-pos pairs, and the first steps of an episode that are
#: never drawn as its positive states (FuRL, the thesis release).
GAP = 10
#: Relay exploration (FuRL, the thesis release): the periods one of which each episode switches
#: agents by, the Gaussian noise on the relay agent's actions (times the action bound) and the
#: positive states that end relay.
RELAY_PERIODS = (50, 100, 150, 200)
RELAY_NOISE = 0.2
RELAY_THRESHOLD = 2500
#: ``env.goal``: one layout per run, restored at every reset (the thesis's protocol), or a new
#: layout at every reset (Metaworld's benchmark setting, FuRL's; the thesis's section 6).
FIXED_GOAL = "fixed"
GOALS = (FIXED_GOAL, "random")
GOAL = FIXED_GOAL
#: Evaluation episodes of the deterministic policy per evaluation (FuRL's code: 10 on random
#: goals).
EVAL_EPISODES = 10

#: The Metaworld camera rendered (the prior implementations').
CAMERA = "corner2"
#: Steps per episode: Metaworld's truncation and the thesis protocol's episode length; a
#: scripted expert is given at least this many to succeed, however short the run's episodes.
MAX_EPISODE_STEPS = 500
#: Shadows, reflections and MSAA off when rendering (about 8x faster on a CPU).
FAST_RENDER = True
#: The side of the rendered frames (the package's small encoder reads 64x64; render LIV's at
#: 224 or 256: an encoder refuses frames far smaller than its own).
IMAGE_SIZE = 64
#: Preloaded positive episodes of the thesis's protocol stage 2 (section 5.1).
STAGE2_POSITIVES = 50
#: The scripted experts' action noise (the stage-2 preloaded positives').
EXPERT_NOISE = 0.1
#: A scripted-expert episode is cut this many steps after its first success.
EXPERT_STEPS_AFTER_SUCCESS = 5

# The offline reward-quality benchmark's dataset (``DatasetSpec``, ``dataset.*``).
#: Successful scripted-expert episodes (the positives).
DATASET_EXPERT_EPISODES = 16
#: Failed episodes of uniform random actions.
DATASET_RANDOM_EPISODES = 6
#: Failed episodes of the scripted expert with a large action noise.
DATASET_FAILED_EXPERT_EPISODES = 6
#: The failed experts' initial action noise (doubled while most of their episodes succeed).
DATASET_FAILURE_NOISE = 2.0
#: Episodes tried per episode wanted, for each kind, before giving up.
DATASET_MAX_ATTEMPTS = 10
