"""avatarjlm's training side: its torch model, trainer and card (the runtime is sparse_body/methods/avatarjlm)."""
