"""wolfcal.sim"""
