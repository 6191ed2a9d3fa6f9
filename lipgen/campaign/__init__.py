"""Campaigns: many datasets (a grid of generate settings) through the stages, on Ray, with one
aggregated report (``lipgen campaign``). ``ray`` is imported only by the executor that uses it."""

from lipgen.campaign.executors import ClusterError, LocalExecutor, RayExecutor, check_address, make_executor
from lipgen.campaign.plan import STAGES, CampaignItem, CampaignPlan, PlanError, load_plan, parse_plan
from lipgen.campaign.run import run_campaign
from lipgen.campaign.store import CampaignError, read_index

__all__ = ["STAGES", "CampaignItem", "CampaignPlan", "PlanError", "load_plan", "parse_plan", "run_campaign",
           "CampaignError", "ClusterError", "read_index", "LocalExecutor", "RayExecutor", "check_address",
           "make_executor"]
