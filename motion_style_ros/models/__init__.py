"""Networks (torch). Only models/ and training/ import torch."""
