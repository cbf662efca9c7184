"""Train the A2C or PPO family (plain, -model, -ldn) on one env, many seeds and K at once.

    python experiments/run.py --env cartpole-v2 --algo ldn --seeds 5 --k 0.5,1,2

The same command as `ldn-jax train ...`; the code is `ldn_jax.host.run`.
"""

import sys

from ldn_jax.host.run import main

if __name__ == "__main__":
    sys.exit(main())
