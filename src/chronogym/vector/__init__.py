"""Vector envs: RayVectorEnv (Ray actors) and SerialVectorEnv (in process), same semantics."""
