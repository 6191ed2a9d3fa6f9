"""Campaigns: many datasets (a grid of generate settings) through the stages, on Ray, with one
aggregated report (``lipgen campaign``). ``ray`` is imported only by the executor that uses it."""

from .executors import ClusterError, LocalExecutor, RayExecutor, check_address, make_executor
from .plan import STAGES, CampaignItem, CampaignPlan, PlanError, load_plan, parse_plan
from .run import run_campaign
from .store import CampaignError, read_index

__all__ = ["STAGES", "CampaignItem", "CampaignPlan", "PlanError", "load_plan", "parse_plan", "run_campaign",
           "CampaignError", "ClusterError", "read_index", "LocalExecutor", "RayExecutor", "check_address",
           "make_executor"]
