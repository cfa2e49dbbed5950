"""The replications of the five published studies (REPLICATION.md): one module per study,
each defining ``STUDY = mitpiv.studies.replication.Study(...)``. ``MODULES`` maps the CLI
name (``mitpiv replicate NAME``) to the module, imported on first use."""

#: study name -> module defining STUDY
MODULES: dict[str, str] = {
    "sapiv-distortion": "mitpiv.studies.replications.sapiv_distortion",
    "channel-tomo": "mitpiv.studies.replications.channel_tomo",
    "multi-plenoptic": "mitpiv.studies.replications.multi_plenoptic",
    "drop-fragments": "mitpiv.studies.replications.drop_fragments",
    "lfpiv-vs-tomo": "mitpiv.studies.replications.lfpiv_vs_tomo",
}
