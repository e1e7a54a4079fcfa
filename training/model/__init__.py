"""The GHNeRF model: small single-purpose modules (nerfstudio style) assembled in :mod:`.ghnerf`."""
from training.model.ghnerf import GHNeRF, LevelConfig, ModelConfig

__all__ = ["GHNeRF", "LevelConfig", "ModelConfig"]
